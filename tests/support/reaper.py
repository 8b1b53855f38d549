"""``python reaper.py REPORT CMD ARGS...``: run CMD as the only child of a child subreaper
(Linux ``PR_SET_CHILD_SUBREAPER``), in a process group of its own as a shell's foreground job,
and report what it left behind.

Writes CMD's pid to ``REPORT.pid`` as soon as it runs; when CMD has ended, writes ``REPORT``:
``{"code": CMD's exit status (negative: the signal that ended it), "left": [[pid, state,
command line], ...]}``, the processes CMD started that were still there (running, or ended but
not reaped: every orphan comes to the subreaper), then kills and reaps them. CMD's stdin, stdout
and stderr are this process's.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import signal
import subprocess
import sys
from pathlib import Path

PR_SET_CHILD_SUBREAPER = 36


def children() -> list[tuple[int, str, str]]:
    """(pid, state, command line) of every process whose parent is this one."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
            cmdline = (entry / "cmdline").read_bytes().replace(b"\0", b" ").decode().strip()
        except OSError:
            continue
        state, ppid = stat.rpartition(")")[2].split()[:2]
        if int(ppid) == os.getpid():
            found.append((int(entry.name), state, cmdline))
    return found


def main() -> None:
    report = Path(sys.argv[1])
    if ctypes.CDLL(None, use_errno=True).prctl(PR_SET_CHILD_SUBREAPER, 1) != 0:
        raise OSError(ctypes.get_errno(), "PR_SET_CHILD_SUBREAPER")
    proc = subprocess.Popen(sys.argv[2:], process_group=0)
    report.with_suffix(".pid").write_text(str(proc.pid))
    code = proc.wait()
    left = children()
    for pid, _state, _cmdline in left:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(ChildProcessError):
            os.waitpid(pid, 0)
    report.write_text(json.dumps({"code": code, "left": left}))


if __name__ == "__main__":
    main()
