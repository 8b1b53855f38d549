"""Errors by kind, each reported by the command line as one clear line with its exit code.

- :class:`InputError` (exit code 2): what the user gave — a scene key or value, an argument, a
  file name, a parameter;
- :class:`BagError` (3): a bag that cannot be read or written (no metadata, truncated, corrupt);
- :class:`IntegrationError` (4): a simulation that cannot go on (non-finite state, Newton
  failure);
- :class:`IdentificationError` (5): data that cannot identify a model (too short, unusable,
  rank-deficient);
- :class:`DegradedRunError` (6): a real-time run whose control path was degraded, with
  ``--strict`` (without it, a warning line);
- :class:`LoopError` (7): a lock-step run that could not go on: a peer of the loop left the
  graph, or did not answer one sample within ``lockstep_timeout_s``.

The message names what is wrong (the key, the file, the time) and is printed without a traceback
by :func:`stillframe.app.cli.main` and by the node executables.
"""

__all__ = ["BY_EXIT_CODE", "BagError", "DegradedRunError", "IdentificationError", "InputError",
           "IntegrationError", "LoopError", "StillframeError"]


class StillframeError(Exception):
    """Base of the errors the user sees as one line; ``exit_code`` is the process's exit code."""

    exit_code = 1


class InputError(StillframeError, ValueError):
    """Bad input from a user: a scene value, a command-line argument, a file, a parameter."""

    exit_code = 2


class BagError(StillframeError):
    """A rosbag2 bag that cannot be read or written; the message names the file at fault."""

    exit_code = 3


class IntegrationError(StillframeError, ArithmeticError):
    """The time integration failed (non-finite state, Newton divergence); the message names the
    step (``integrator.dt``) and the time."""

    exit_code = 4


class IdentificationError(StillframeError):
    """The data cannot identify a model: too few samples for the order, no usable Hankel
    singular values, a realization that breaks a method's assumptions."""

    exit_code = 5


class DegradedRunError(StillframeError):
    """A run ``launch --strict`` refuses: a real-time run whose result cannot be trusted, or one
    beside a foreign writer; the message gives the reasons (:mod:`stillframe.app.run_verdict`)."""

    exit_code = 6


class LoopError(StillframeError):
    """A lock-step run ended before its end: the simulator never advances without the command of
    the current sample, and the peer that owes it left the graph or did not answer within
    ``lockstep_timeout_s``. The message names the peer and the sample; the result written is
    partial (``"complete": false``)."""

    exit_code = 7


#: the kinds of error by exit code, for a process that reports one of another's (a launch's
#: node): its one line and its code are passed on
BY_EXIT_CODE: dict[int, type[StillframeError]] = {
    kind.exit_code: kind for kind in (InputError, BagError, IntegrationError, IdentificationError,
                                      DegradedRunError, LoopError)}
