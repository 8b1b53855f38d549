"""Ctrl-C (SIGINT) and SIGTERM at any moment of a process, from its first line to its last: one
line on stderr and the exit code of the signal (130, 143), never a traceback.

A process entry point (``stillframe``'s :func:`stillframe.app.cli.main`, a node's ``python -m
PACKAGE``, :func:`run_module`) goes through three phases, each with its handler:

- **starting** (:func:`starting`, its first act, before the heavy imports): nothing is open
  and no child runs yet, so a signal writes the line and ends the process at once. A
  KeyboardInterrupt raised inside numpy's or scipy's imports would print their traceback.
- **working** (:func:`working`): a signal raises :class:`KeyboardInterrupt` (SIGTERM:
  :class:`Terminated`, a KeyboardInterrupt), so that ``finally`` blocks and context managers run
  (a bag closed, children stopped and reaped, temporary files removed); the entry point's
  :func:`run_work` catches it and writes the line. The middleware's own handlers
  (``api.install_signal_handlers``) take over once a node exists: a spinning node ends its loop
  cleanly. The signal is also noted, because a KeyboardInterrupt raised at an arbitrary line
  does not always arrive as one: raised in a C extension's initialisation it comes back as that
  module's ImportError (pybind11: "initialization failed"), a library's bare ``except`` may
  end it, and raised in a finaliser Python can only print it ("Exception ignored in ...") and go
  on (then it is raised again in the main thread). Whatever the work then raises or returns,
  the entry point answers the noted signal.
- **ending** (:func:`finish`): the work is done; the output is flushed under the handler of
  the starting phase, the functions of :func:`at_finish` run, and the process ends there with
  its code (``os._exit``). The interpreter's own teardown after that (clearing the modules,
  which takes a while after numpy, scipy and numba) would run with the default handlers, where
  a signal kills the process without its line; what it would do is done by the work itself
  (bags closed, nodes destroyed, children reaped and temporary files removed by their context
  managers; logging flushed here), and the rest of ``atexit`` is libraries' shutdown flags and
  caches.

Before the interpreter runs the entry point's first line (its own start-up, ``site``) a signal is
Python's: it ends the process by the signal, or with Python's own KeyboardInterrupt message.
"""

from __future__ import annotations

import _thread
import contextlib
import os
import signal
import sys
import threading
from collections.abc import Callable
from types import FrameType
from typing import Any, NoReturn

#: the signals an entry point answers as an interruption
SIGNALS = (signal.SIGINT, signal.SIGTERM)


class Terminated(KeyboardInterrupt):
    """SIGTERM in the working phase: a KeyboardInterrupt (everything that cleans up on Ctrl-C
    cleans up on it) that remembers its signal for the exit code."""

    signum = signal.SIGTERM


def exit_code(exc: BaseException | None = None) -> int:
    """The exit code of an interruption: 128 + the signal (a shell's code of a process the
    signal ended): 130 for SIGINT, 143 for SIGTERM."""
    return 128 + getattr(exc, "signum", signal.SIGINT)


def _say(line: str) -> None:
    with contextlib.suppress(OSError):     # stderr closed: the exit code still says it
        os.write(2, f"{line}\n".encode(errors="replace"))


def _exit_now(prog: str) -> Any:
    def handler(signum: int, _frame: FrameType | None) -> None:
        _say(f"{prog}: interrupted")
        _end(128 + signum)

    return handler


#: the signal the working phase received (None: none)
_received: int | None = None


def _raise(signum: int, frame: FrameType | None) -> None:
    global _received
    _received = signum
    if signum == signal.SIGTERM:
        raise Terminated
    signal.default_int_handler(signum, frame)


def _unraisable(unraisable: Any) -> None:
    """A KeyboardInterrupt that a finaliser swallowed is raised again in the main thread, once
    this hook has returned (raised in here, Python would print it and drop it again): a thread
    waits for the hook to end, then interrupts the main thread. Anything else goes to Python's
    own hook."""
    if not isinstance(unraisable.exc_value, KeyboardInterrupt):
        sys.__unraisablehook__(unraisable)
        return
    signum = getattr(unraisable.exc_value, "signum", signal.SIGINT)
    left = threading.Event()

    def again() -> None:
        left.wait()
        _thread.interrupt_main(signum)

    try:
        threading.Thread(target=again, name="interrupt again", daemon=True).start()
    except RuntimeError:        # no thread any more (the interpreter is ending): end here
        _say("interrupted")
        _end(128 + signum)
    left.set()


def _install(handler: Any) -> None:
    for signum in SIGNALS:
        signal.signal(signum, handler)


def starting(prog: str) -> None:
    """A process's first act: a signal from now on writes ``{prog}: interrupted`` and ends the
    process at once with its exit code."""
    _install(_exit_now(prog))


def working() -> None:
    """The work begins: a signal raises KeyboardInterrupt (or :class:`Terminated`) so that
    everything begun cleans up; the entry point answers it (:func:`run_work`)."""
    global _received
    _received = None
    _install(_raise)
    sys.unraisablehook = _unraisable


def received() -> bool:
    """Whether the working phase received a signal (an error the work reports after it may be
    the interruption in another form: :func:`run_work` answers it)."""
    return _received is not None


def run_work(prog: str, work: Callable[[], int]) -> int:
    """``work()``'s exit code, or, when it was interrupted, ``{prog}: interrupted`` on stderr
    and 128 + the signal: a KeyboardInterrupt, any exception raised after a signal in the
    working phase, or a normal end after one (the interruption swallowed on the way), unless
    the work returned that code itself (it has said so). An interruption is answered once: the
    signal is forgotten then."""
    global _received
    try:
        code = work()
    except KeyboardInterrupt as exc:
        code = -exit_code(exc)
    except Exception:
        if _received is None:
            raise
        code = -(128 + _received)
    if _received is not None and code >= 0:
        answered = code == 128 + _received         # the work said so itself (launch does)
        code = code if answered else -(128 + _received)
        _received = None if answered else _received
    if code < 0:
        _say(f"{prog}: interrupted")
        code = -code
        _received = None
    return code


def ending(prog: str) -> None:
    """The work is done and reported: a signal from now on ends the process at once, as in
    :func:`starting`."""
    _install(_exit_now(prog))


#: what :func:`finish` runs before the process ends, in order (what ``atexit`` would have run
#: that matters: a tap on stderr passing on its last bytes)
_at_finish: list[Callable[[], None]] = []


def at_finish(function: Callable[[], None]) -> None:
    """Run ``function`` in :func:`finish`, after the output is flushed (a process that ends
    otherwise runs its ``atexit`` functions instead: register it there too)."""
    _at_finish.append(function)


def finish(prog: str, code: int) -> NoReturn:
    """A process entry point's last act: :func:`ending`, its output flushed and the functions
    of :func:`at_finish` run, then the process ends with ``code`` without the interpreter's
    teardown (module docstring)."""
    ending(prog)
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):     # a reader gone, a stream closed
            stream.flush()
    if "logging" in sys.modules:
        sys.modules["logging"].shutdown()
    _end(code)


def _end(code: int) -> NoReturn:
    """The functions of :func:`at_finish` (a line written to a tapped stderr just before reaches
    the real one), then the process ends with ``code`` at once."""
    for function in _at_finish:
        with contextlib.suppress(Exception):    # ending anyway: one failure must not hold it
            function()
    os._exit(code)


def run_module(module: str, prog: str) -> NoReturn:
    """A node executable's ``python -m PACKAGE``: the handlers of :func:`starting` before
    ``module`` is imported (numpy, the middleware), then its ``main()`` as the work, then
    :func:`finish`; an interruption is one line and its exit code."""
    starting(prog)
    import importlib

    imported = importlib.import_module(module)
    sys.argv[0] = imported.__file__ or sys.argv[0]     # as ``python -m MODULE`` would have it
    working()
    finish(prog, run_work(prog, lambda: int(imported.main() or 0)))
