"""stillframe: simulate, identify and control a flexible frame with a pendulum damper."""

__version__ = "0.1.0"
