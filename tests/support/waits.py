"""How long a test waits for an event before it calls the wait a hang.

A test waits for the event it tests (a match on the graph, a line, a sample, a process's exit)
and goes on the moment it comes, so a wall-clock limit on such a wait only ends a hang. It is
long because a loaded machine (two busy loops, other test runs beside this one) can take tens of
seconds where a quiet one takes milliseconds; a test that must tell "soon" from "late" forces
that difference instead (a lease of minutes, a stopped process), never with a short limit."""

from __future__ import annotations

#: wall seconds after which a wait for an event is a hang
HANG_S = 300.0
