"""The closed loop: lock-step in one process, its evaluation, and what the loop nodes share."""
