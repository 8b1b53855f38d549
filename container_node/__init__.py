"""The estimator and the controller composed in one process (``stillframe launch --compose``)."""
