"""modal_tracker: the structure's modes, identified again every few seconds from a sliding window
of live samples (docs/identification-tool.md, "Live modal tracking").

A thin shell around :class:`stillframe.identification.tracker.ModalTracker`. Parameters:

- ``inputs``, ``outputs``: channels ``TOPIC[:FIELD]`` as for ``stillframe identify`` (no inputs:
  output-only SSI-COV); the message type of each topic comes from the topic contract;
- ``rate_hz`` (32.0): the sample rate of the channels; ``window_s`` (60.0): the window;
  ``update_period_s`` (5.0): how often the window is identified; ``order`` ("auto");
  ``record_file`` (""): append each update as a JSON line there (``launch --track``);
  ``idle`` (false): the process at SCHED_IDLE; ``reliable`` (false): read RELIABLE and
  TRANSIENT_LOCAL, :data:`READ_DEPTH` deep (a lock-step loop's writers: every sample).

At a high sensor rate, read the simulator's decimated taps (``/_decimated<topic>``, anti-alias
filtered and thinned at the writer, :mod:`stillframe.loop.decimated_taps`) at their rate
(``launch --track`` does): a reader of the topics themselves costs their writer a send per sample.

Samples are aligned by header stamp, and an update is due every ``update_period_s`` of sample
time (the stamps: sim time in lock-step, which runs faster than the wall clock). Each due window
is copied and identified on a worker thread of this process, in order, so the callbacks keep
taking samples. In real time, more than :data:`MAX_PENDING` windows waiting are skipped
(counted); in lock-step (``reliable``) every due window waits its turn (up to
:data:`MAX_PENDING_BYTES` of samples), so that the updates are the same on any machine. On
shutdown the waiting ones are finished first. This process is not in the loop's path: it only
subscribes.
Each update publishes ``identification/modes`` (``std_msgs/msg/Float64MultiArray``, layout in
:mod:`stillframe.identification.tracker`) and a status on ``/diagnostics`` (modes, window,
updates, skipped updates, last error).
"""

from __future__ import annotations

import json
import sys
from concurrent.futures import CancelledError, Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from stillframe import interrupts
from stillframe.bags.channels import Channel, field_reader, stamp_ns
from stillframe.contract import messages, topics
from stillframe.errors import InputError
from stillframe.identification.tracker import (
    EXIT_GIVEN_UP,
    GIVEN_UP,
    MODES_TOPIC,
    TRACKER_READY,
    ModalTracker,
    TrackedModes,
    Window,
    identify_window,
    modes_array,
    no_modes,
)
from stillframe.loop.decimated_taps import undecimated
from stillframe.middleware import api
from stillframe.middleware.qos import SENSOR_DATA, Durability, Reliability
from stillframe.node_runtime.parameters import NodeParameters, declare, limited, param, positive
from stillframe.node_runtime.realtime import run_idle
from stillframe.node_runtime.support import OK, WARN, Diagnostics

MAX_PENDING = 4
"""Windows waiting for the worker beyond which a due update is skipped, in real time."""
MAX_PENDING_BYTES = 512 * 2**20
"""In lock-step (``reliable``): the samples the waiting windows may hold [bytes] beyond which a
due update is skipped. A lock-step loop outruns the identifications (at 32 Hz it runs a 5 s
update period in a tenth of a second, one identification takes a second), and skipping there
would make its updates depend on the machine's speed; this bound only guards memory (it is
some 700 windows of 60 s of four channels at 200 Hz)."""
READ_DEPTH = 1000
"""Samples a ``reliable`` subscription holds for a callback that falls behind."""


def contract_type(topic: str) -> str:
    """The message type the topic contract gives ``topic`` (absolute or in the namespace), or
    the topic a decimated tap thins (:mod:`stillframe.loop.decimated_taps`)."""
    topic = undecimated(topic)
    for spec in topics.CONTRACT:
        if topic in (spec.name, f"{topics.DEFAULT_NAMESPACE}/{spec.name}"):
            return spec.type_name
    raise InputError(f"modal_tracker: {topic} is not a topic of the contract")


def _some(value: list[str]) -> str | None:
    return None if any(value) else "give at least one output channel"


def _order(value: str) -> str | None:
    return None if value == "auto" or (value.isdigit() and int(value) >= 1) else \
        "expected auto or a whole number >= 1"


@dataclass(frozen=True)
class TrackerParameterValues(NodeParameters):
    """modal_tracker (module docstring)."""

    inputs: list[str] = param([""], doc=(
        "input channels `TOPIC[:FIELD]` (empty strings ignored); none: output-only SSI-COV"))
    outputs: list[str] = param([""], limited(_some, "at least one"), doc=(
        "output channels `TOPIC[:FIELD]`"))
    rate_hz: float = param(32.0, positive, unit="Hz", doc="sample rate of the channels")
    window_s: float = param(60.0, positive, unit="s", doc="the sliding window")
    update_period_s: float = param(5.0, positive, unit="s", doc=(
        "sample time between identifications of the window"))
    order: str = param("auto", limited(_order, "auto or >= 1"), doc="model order")
    record_file: str = param("", doc="append each update as a JSON line here; empty: none")
    idle: bool = param(False, doc="the whole process at SCHED_IDLE")
    reliable: bool = param(False, doc=(
        "read RELIABLE and TRANSIENT_LOCAL, READ_DEPTH deep (a lock-step loop's writers)"))


class ModalTrackerNode:
    """The ``modal_tracker`` node the module's docstring describes: its parameters declared on
    ``node``, one subscription per channel, the tracker's window fed with aligned samples and
    identified on a worker thread."""

    def __init__(self, node: api.Node) -> None:
        self.node = node
        values = declare(node, TrackerParameterValues)
        inputs = [Channel.parse(s) for s in values.inputs if s]
        outputs = [Channel.parse(s) for s in values.outputs if s]
        period = values.update_period_s
        self.idle = values.idle
        self.record_file = Path(values.record_file) if values.record_file else None
        self.tracker = ModalTracker(1.0 / values.rate_hz, values.window_s,
                                    "auto" if values.order == "auto" else int(values.order))
        self.channels = [*inputs, *outputs]
        self.n_inputs = len(inputs)
        self.pending: dict[int, list[float | None]] = {}
        self.start_ns: int | None = None
        self.readers = []
        # lock-step (``reliable``): every sample, as the loop's own readers take them
        qos = (replace(SENSOR_DATA, reliability=Reliability.RELIABLE,
                       durability=Durability.TRANSIENT_LOCAL, depth=READ_DEPTH)
               if values.reliable else "sensor_data")
        for k, channel in enumerate(self.channels):
            msgtype = contract_type(channel.topic)
            _, read = field_reader(channel, msgtype)
            node.create_subscription(msgtype, channel.topic,
                                     lambda msg, k=k, read=read: self.on_sample(k, msg, read),
                                     qos)
        self.modes_pub = node.create_publisher("std_msgs/msg/Float64MultiArray", MODES_TOPIC, 10)
        self.diagnostics = Diagnostics(node, period)
        self.pool = ThreadPoolExecutor(max_workers=1)
        #: the windows submitted and not identified yet, each with its future
        self.pending_updates: list[tuple[Future, Window]] = []
        self.reliable = values.reliable
        self.period = period
        self.next_update: float | None = None
        self.updates = self.skipped = 0
        self.given_up = False
        if self.idle:
            # SCHED_IDLE once set up (the worker thread, started later, inherits it): beside
            # busy processes an idle one gets next to no CPU time, and the launch waits for the
            # ready line before it starts the loop
            run_idle()

    def on_sample(self, k: int, msg: object, read) -> None:
        """The value ``read`` takes from channel ``k``'s message, filed under its header stamp; once
        every channel of a stamp is in, the row joins the tracker's window, older incomplete rows
        are dropped and an update is submitted when due (:meth:`maybe_update`). A message without a
        stamp is ignored."""
        stamp = stamp_ns(msg)
        if stamp is None:
            return
        row = self.pending.setdefault(stamp, [None] * len(self.channels))
        row[k] = read(msg)
        if all(v is not None for v in row):
            del self.pending[stamp]
            self.start_ns = stamp if self.start_ns is None else self.start_ns
            self.tracker.add(stamp * 1e-9, row[: self.n_inputs],
                             row[self.n_inputs:])
            for old in [s for s in self.pending if s < stamp]:
                del self.pending[old]
            self.maybe_update(stamp * 1e-9)

    def maybe_update(self, t: float) -> None:
        """Submit the window when an update is due (sample time) and the window half full."""
        if self.next_update is None:
            self.next_update = t + self.period
        if t < self.next_update or self.tracker.samples < 0.5 * self.tracker.capacity:
            return
        self.next_update = t + self.period
        self.pending_updates = [(f, w) for f, w in self.pending_updates if not f.done()]
        window = self.tracker.window()
        if (sum(_size(w) for _, w in self.pending_updates) + _size(window) > MAX_PENDING_BYTES
                if self.reliable else len(self.pending_updates) >= MAX_PENDING):
            self.skipped += 1
            return
        future = self.pool.submit(identify_window, window)
        future.add_done_callback(lambda f, t=window.t: self.identified(f, t))
        self.pending_updates.append((future, window))

    def identified(self, future: Future, t: float) -> None:
        """Publish a window's update; an identification that raised what
        :func:`identify_window` does not expect is published as that window's error, not lost
        (the tracker runs on beside the loop)."""
        if self.given_up:
            return              # written as given up by finish()
        try:
            tracked = future.result()
        except CancelledError:
            return
        except Exception as exc:
            tracked = no_modes(t, f"the identification failed: {type(exc).__name__}: {exc}")
        self.publish(tracked)

    def finish(self) -> None:
        """On stop: identify the windows already due, then return. The loop is gone by now
        (a launch stops the tracker after the nodes), so an idle tracker leaves SCHED_IDLE: on
        a busy machine it would otherwise wait for CPU time nobody leaves. Asked again to stop
        meanwhile: the windows still due are given up and the process ends at once (the
        worker's identification cannot be interrupted, and its thread would hold the exit)."""
        if self.idle:
            run_idle(False)
        try:
            self.pool.shutdown(wait=True)
        except KeyboardInterrupt:
            self.given_up = True
            due = [(f, w) for f, w in self.pending_updates if not f.done()]
            for future, window in due:
                future.cancel()
                self.write(no_modes(window.t, f"{GIVEN_UP}: the tracker was stopped again "
                                              "before this window was identified"))
            print(f"modal_tracker: stopped again while identifying; windows still due, given "
                  f"up: {len(due)} (written as such to {self.record_file or 'no record file'})",
                  file=sys.stderr, flush=True)
            interrupts.finish("modal_tracker", EXIT_GIVEN_UP)

    def write(self, tracked: TrackedModes) -> None:
        """Append the update to ``record_file`` as a JSON line (none set: nothing)."""
        if self.record_file is not None:
            with self.record_file.open("a") as stream:
                stream.write(json.dumps(tracked.record()) + "\n")

    def publish(self, tracked: TrackedModes) -> None:
        """Publish one update: the JSON line to ``record_file`` (if set), the modes on
        ``identification/modes`` and a status on ``/diagnostics``."""
        self.updates += 1
        self.write(tracked)
        dims, data = modes_array(tracked)
        msg = messages.new("std_msgs/msg/Float64MultiArray")
        msg.layout.dim = [messages.new("std_msgs/msg/MultiArrayDimension", label=label,
                                       size=size, stride=stride) for label, size, stride in dims]
        msg.data = np.asarray(data, dtype=float)
        self.modes_pub.publish(msg)
        values = {"modes": len(tracked.frequency_hz), "window_samples": self.tracker.samples,
                  "updates": self.updates, "skipped_updates": self.skipped,
                  "filled_samples": self.tracker.filled, "window_restarts": self.tracker.restarts}
        for i, row in enumerate(tracked.rows()):
            values[f"mode{i + 1}"] = f"{row[0]:.4g} Hz, zeta {row[1]:.3g}"
        level = OK if tracked.error is None and not tracked.warnings else WARN
        self.diagnostics.publish(self.start_ns or 0, values, level,
                                 tracked.error or "; ".join(tracked.warnings))


def _size(window: Window) -> int:
    """The bytes of samples a window holds."""
    return window.u.nbytes + window.y.nbytes


@api.node_main
def main() -> int:
    """Run the node (console script ``modal_tracker``); bad parameters exit 2 with one line."""
    node = api.create_node("modal_tracker", namespace=topics.DEFAULT_NAMESPACE)
    tracker = None
    try:
        tracker = ModalTrackerNode(node)
        node.get_logger().info(TRACKER_READY)   # the launcher starts the loop after this
        api.spin(node)
    finally:
        if tracker is not None:
            tracker.finish()
        node.destroy_node()
    return 0


if __name__ == "__main__":
    sys.exit(main())
