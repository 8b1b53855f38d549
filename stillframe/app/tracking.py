"""``stillframe launch SCENE --track``: the modal tracker beside the loop.

The tracker (``identification``'s ``modal_tracker``) subscribes to the excitation's load cell
and the three floor accelerometers, identifies its window every few seconds and appends each
update, as one JSON line, to a file the launcher reads at the end: the launch JSON's
``tracked_modes``, a list of ``{"t": …, "modes": [{"frequency_hz", "damping_ratio",
"frequency_ci", "damping_ci"}], "warnings": […], "error": …}`` with ``t`` the window's last sample
time [s] (sim time). It only subscribes, in its own process: it cannot hold the loop up; and it
runs at SCHED_IDLE in a real-time run (``idle``), so its identifications take only CPU time the
nodes leave. In lock-step there are no deadlines, and an idle tracker could be starved of the
time it needs to finish its windows when it is stopped.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

from stillframe.config.scene import Scene
from stillframe.contract import topics
from stillframe.identification.tracker import GIVEN_UP
from stillframe.loop.decimated_taps import decimated_topic, decimation_factor

TRACKER = "modal_tracker"
TRACKER_MODULE = "identification"
#: the tracker's window and update period, as fractions of the scene's duration (at most 60 s
#: and 5 s)
WINDOW_S, UPDATE_S = 60.0, 5.0
#: how long a launch waits for the tracker to finish the windows due when it stops it [s]: at
#: most the tracker's queue (identification.node.MAX_PENDING) and the one identifying, however
#: slow the machine (a second Ctrl-C of the launch ends it at once)
TRACKER_STOP_S = 300.0


def tracker_command(scene: Scene, record_file: Path, *, lockstep: bool) -> list[str]:
    """``python -m identification --ros-args -p …`` for the scene's rate and channels: the
    simulator's decimated taps at their rate where it publishes them, else the topics; in real
    time (not ``lockstep``) at SCHED_IDLE (only CPU time the nodes leave), in lock-step reading
    reliably (every sample, as the loop's readers)."""
    factor = decimation_factor(scene.sensors.rate_hz)

    def topic(spec: topics.TopicSpec) -> str:
        name = f"{topics.DEFAULT_NAMESPACE}/{spec.name}"
        return decimated_topic(name) if factor > 1 else name

    window = min(WINDOW_S, scene.duration / 2)
    params = {"inputs": [topic(topics.EXCITATION_WRENCH)],
              "outputs": [topic(spec) for spec in topics.FLOOR_IMU],
              "rate_hz": float(scene.sensors.rate_hz) / factor,
              "window_s": window, "update_period_s": min(UPDATE_S, window / 2),
              "record_file": str(record_file), "idle": not lockstep, "reliable": lockstep}
    argv = [sys.executable, "-m", TRACKER_MODULE, "--ros-args"]
    for name, value in params.items():
        argv += ["-p", f"{name}:={value if isinstance(value, str) else json.dumps(value)}"]
    return argv


def given_up(tracked: list[dict[str, Any]]) -> str:
    """The launch's warning on the windows the tracker gave up at its stop (their updates say
    so in ``error``), "" when none."""
    times = [u["t"] for u in tracked if (u.get("error") or "").startswith(GIVEN_UP)]
    if not times:
        return ""
    return (f"the modal tracker gave up the windows due at its stop (t = "
            f"{', '.join(f'{t:g}' for t in times)} s): their identification did not end within "
            f"the {TRACKER_STOP_S:g} s the stop allows; tracked_modes holds them with that error")


def read_tracked(record_file: Path) -> list[dict[str, Any]]:
    """The tracker's updates (JSON lines; a last line cut by the tracker's stop is dropped)."""
    if not record_file.is_file():
        return []
    out = []
    for line in record_file.read_text().splitlines():
        try:
            out.append(json.loads(line))
        except ValueError:
            continue
    return out
