"""A run's token (docs/nodes.md, writer identity): drawn once per launch, given to every node as
its ``run_token`` parameter; each stamped sample a node writes carries it, and a node takes only
the samples that do.

This module imports the standard library only: ``ros_ws/launch/closed_loop.launch.py`` loads
it by its path in the Python of a ROS 2 installation, where stillframe's dependencies are not.
"""

from __future__ import annotations

import secrets

#: what a token may hold, as a parameter's error names it
TOKEN_LIMITS = "letters, digits, - and _; at most 64"


def new_run_token() -> str:
    """A new run's token: 64 random bits, hex, after a ``t``. The letter keeps it a string where
    ROS reads a parameter's value as YAML: bare hex digits can read as a number (``12e45…`` as
    inf, all digits as an integer), which a string parameter refuses."""
    return "t" + secrets.token_hex(8)


def token_problem(value: str) -> str | None:
    """Why ``value`` is no token (None: it is one)."""
    ok = len(value) <= 64 and all(c.isascii() and (c.isalnum() or c in "-_") for c in value)
    return None if ok else f"expected {TOKEN_LIMITS}"
