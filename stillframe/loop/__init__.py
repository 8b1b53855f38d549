"""The closed loop in one process, its evaluation, and what every process of the loop agrees
on (sample assembly, force matching, pacing, watchdogs, writer and command gates, wiring)."""
