"""Input and output channels for identification, read from a rosbag2 bag.

A channel is ``TOPIC[:FIELD]``: FIELD is a dotted path into the message, with ``[i]`` for an
element of an array (``wrench.force.x``, ``position[0]``). Without FIELD the topic contract's
quantity for the topic's type is taken (docs/architecture.md, topic contract). Bags are read with
:func:`stillframe.bags.storage.open_bag`, so sqlite3 and MCAP bags, including ones written by
``ros2 bag record``, are read alike; a lone ``.mcap`` file with :mod:`stillframe.bags.lone_mcap`.
A bag with a damaged part (a chunk whose CRC fails, a damaged index) is refused, naming it:
identification needs every sample.
Each sample is placed at its header stamp (the measurement time in the contract), or at its log
time when the message has no header or all its stamps are zero. Channels must be uniformly
sampled at one rate without gaps; they are aligned sample by sample on their common time span.
Preprocessing applies the same linear filter to inputs and outputs, so the input-output relation
that identification estimates is kept.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy import signal

from stillframe.bags.lone_mcap import is_lone_mcap, open_lone_mcap
from stillframe.bags.storage import open_bag, refuse_damage
from stillframe.contract.messages import TYPESTORE
from stillframe.contract.topics import CONDITIONAL, CONTRACT
from stillframe.errors import BagError, IdentificationError, InputError

__all__ = ["DEFAULT_FIELDS", "Channel", "Record", "Series", "align", "field_reader", "preprocess",
           "read_record", "read_series", "stamp_ns"]

#: Default field per message type: that of the first contract topic of the type, and std_msgs'
#: Float64's ``data``.
DEFAULT_FIELDS: dict[str, str] = {"std_msgs/msg/Float64": "data"} | {
    spec.type_name: spec.field for spec in reversed(CONTRACT) if spec.field}
#: Largest deviation of one sampling step from the median step, relative to the median step.
DEFAULT_JITTER = 0.05

#: SI unit of a field by its message member (REP 103; JointState of a revolute joint: rad)
FIELD_UNITS: dict[str, str] = {
    "linear_acceleration": "m/s²", "angular_velocity": "rad/s", "force": "N", "torque": "N m",
    "position": "rad", "velocity": "rad/s", "effort": "N m"}

_PATH_ITEM = re.compile(r"^([A-Za-z_]\w*)((?:\[\d+\])*)$")


@dataclass(frozen=True)
class Channel:
    """One scalar signal: a topic and a field path inside its messages (None: the default)."""

    topic: str
    field: str | None = None

    @classmethod
    def parse(cls, spec: str) -> Channel:
        """Parse ``TOPIC[:FIELD]``; the topic must be absolute (``/frame/floor1/imu``)."""
        topic, _, path = spec.partition(":")
        if not topic.startswith("/") or len(topic) < 2:
            raise InputError(f"channel {spec!r}: the topic must be absolute, "
                             "e.g. /frame/floor1/imu")
        if path:
            _split_path(path, spec)
        return cls(topic, path or None)

    @property
    def unit(self) -> str | None:
        """The SI unit of the field (:data:`FIELD_UNITS`), None when unknown."""
        for part in (self.field or "").split("."):
            if (unit := FIELD_UNITS.get(part.split("[")[0])) is not None:
                return unit
        return None

    def __str__(self) -> str:
        return f"{self.topic}:{self.field}" if self.field else self.topic


@dataclass(frozen=True)
class Series:
    """The samples of one channel: integer stamps [ns] and values."""

    channel: Channel
    stamps_ns: np.ndarray
    values: np.ndarray
    stamp_source: str  # "header" or "log time"


@dataclass(frozen=True)
class Record:
    """Aligned, uniformly sampled input and output channels ready for identification."""

    bag: str
    inputs: tuple[Channel, ...]
    outputs: tuple[Channel, ...]
    t: np.ndarray  # (N,) seconds from the first aligned sample
    u: np.ndarray  # (N, m)
    y: np.ndarray  # (N, p)
    dt: float
    start_ns: int
    preprocessing: dict = field(default_factory=dict)

    @property
    def samples(self) -> int:
        """The number of samples in the record."""
        return len(self.t)


def _split_path(path: str, spec: str) -> list[tuple[str, list[int]]]:
    items = []
    for part in path.split("."):
        match = _PATH_ITEM.match(part)
        if match is None:
            raise InputError(f"channel {spec!r}: bad field path {path!r} "
                             "(dotted names with optional [index], e.g. wrench.force.x)")
        items.append((match.group(1), [int(i) for i in re.findall(r"\d+", match.group(2))]))
    return items


def _default_field(topic: str, msgtype: str) -> str:
    """The contract's field for a contract topic (matched by its name under any namespace),
    else the type's default."""
    for spec in (*CONTRACT, *CONDITIONAL):
        if spec.field and spec.type_name == msgtype and topic.endswith("/" + spec.name):
            return spec.field
    if msgtype not in DEFAULT_FIELDS:
        raise InputError(f"topic {topic} has type {msgtype}, which has no default field; "
                         f"give one as {topic}:FIELD")
    return DEFAULT_FIELDS[msgtype]


def _extract(msg: object, path: list[tuple[str, list[int]]], channel: Channel,
             msgtype: str) -> float:
    value = msg
    for name, indices in path:
        if not hasattr(value, name) or name.startswith("_"):
            raise InputError(f"channel {channel}: type {msgtype} has no field {name!r} "
                             f"(in {channel.field!r})")
        value = getattr(value, name)
        for index in indices:
            try:
                value = value[index]
            except (IndexError, TypeError):
                raise InputError(f"channel {channel}: {name}[{index}] is out of range or not "
                                 f"an array in a {msgtype} message") from None
    if isinstance(value, bool) or not isinstance(value, int | float | np.number):
        raise InputError(f"channel {channel}: field {channel.field!r} is not a number "
                         f"({type(value).__name__}); give a path to a numeric field")
    return float(value)


def field_reader(channel: Channel, msgtype: str) -> tuple[Channel, Callable[[object], float]]:
    """The channel with its field resolved (the contract's default when none is given) and a
    function reading that field's value from a deserialised message (for live subscribers such
    as the modal tracker)."""
    full = Channel(channel.topic, channel.field or _default_field(channel.topic, msgtype))
    path = _split_path(full.field, str(full))
    return full, functools.partial(_read_field, path=path, channel=full, msgtype=msgtype)


def _read_field(msg: object, *, path: list[tuple[str, list[int]]], channel: Channel,
                msgtype: str) -> float:
    return _extract(msg, path, channel, msgtype)


def stamp_ns(msg: object) -> int | None:
    """The ``header.stamp`` of ``msg`` in nanoseconds, or None for a message without a header."""
    header = getattr(msg, "header", None)
    stamp = getattr(header, "stamp", None)
    if stamp is None:
        return None
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def read_series(bag: str | Path, channels: Sequence[Channel]) -> list[Series]:
    """Read each channel's samples from the bag (one pass over the needed topics)."""
    opener = open_lone_mcap if is_lone_mcap(bag) else open_bag
    with opener(bag, TYPESTORE) as reader:
        refuse_damage(reader)
        types: dict[str, set[str]] = {}
        for c in reader.connections:
            types.setdefault(c.topic, set()).add(c.msgtype)
        missing = sorted({ch.topic for ch in channels} - types.keys())
        if missing:
            raise InputError(f"bag {bag} has no topic {', '.join(missing)} "
                             f"(topics: {', '.join(sorted(types)) or 'none'})")
        resolved = []
        for ch in channels:
            if len(types[ch.topic]) > 1:
                raise InputError(f"topic {ch.topic} carries several types in bag {bag}: "
                                 f"{', '.join(sorted(types[ch.topic]))}")
            (msgtype,) = types[ch.topic]
            full = Channel(ch.topic, ch.field or _default_field(ch.topic, msgtype))
            resolved.append((full, _split_path(full.field, str(full)), msgtype))
        topics = {ch.topic for ch in channels}
        wanted = [c for c in reader.connections if c.topic in topics]
        stamps: dict[str, list[int | None]] = {t: [] for t in topics}
        logtimes: dict[str, list[int]] = {t: [] for t in topics}
        values: list[list[float]] = [[] for _ in resolved]
        corrupt: dict[str, list] = {}     # topic: [count, first log time, reason]
        for connection, logtime, raw in reader.messages(connections=wanted):
            try:
                msg = reader.deserialize(raw, connection.msgtype)
            except Exception as exc:    # rosbags raises struct, index, value, unicode errors
                seen = corrupt.setdefault(connection.topic, [0, logtime, type(exc).__name__])
                seen[0] += 1
                continue
            stamps[connection.topic].append(stamp_ns(msg))
            logtimes[connection.topic].append(logtime)
            for i, (full, items, msgtype) in enumerate(resolved):
                if full.topic == connection.topic:
                    values[i].append(_extract(msg, items, full, msgtype))
    if corrupt:
        raise BagError(f"bag {bag}: messages that do not decode (corrupt CDR): " + "; ".join(
            f"{topic}: {n} of {n + len(stamps[topic])}, the first at log time {first} ns "
            f"({reason})" for topic, (n, first, reason) in sorted(corrupt.items())))
    out = []
    for (full, _, _), vals in zip(resolved, values, strict=True):
        header = stamps[full.topic]
        if not header:
            raise IdentificationError(f"bag {bag}: topic {full.topic} has no messages")
        use_header = all(s is not None for s in header) and any(header)
        order_ns = np.asarray(header if use_header else logtimes[full.topic], dtype=np.int64)
        out.append(Series(full, order_ns, np.asarray(vals, dtype=float),
                          "header" if use_header else "log time"))
    return out


def _check_uniform(series: Series, max_jitter: float) -> float:
    """Median step [ns]; refuse duplicates, non-uniform steps and gaps, saying where."""
    ch, stamps = series.channel, series.stamps_ns
    if len(stamps) < 3:
        raise IdentificationError(f"channel {ch}: only {len(stamps)} samples")
    order = np.argsort(stamps, kind="stable")
    stamps = stamps[order]
    steps = np.diff(stamps).astype(float)
    step = float(np.median(steps))
    if step <= 0:
        raise IdentificationError(f"channel {ch}: most {series.stamp_source} stamps are repeated")
    ratio = steps / step
    nearest = np.rint(ratio)
    t0 = stamps[0]
    bad = np.flatnonzero((nearest < 1) | (np.abs(ratio - nearest) > max_jitter))
    if bad.size:
        k = bad[0]
        raise IdentificationError(
            f"channel {ch}: sampling is not uniform: step {steps[k] / 1e6:.6g} ms at "
            f"t = {(stamps[k] - t0) / 1e9:.6g} s ({series.stamp_source}) against a median of "
            f"{step / 1e6:.6g} ms ({bad.size} such steps; allowed jitter {max_jitter:.0%})")
    gaps = np.flatnonzero(nearest > 1)
    if gaps.size:
        k = gaps[0]
        raise IdentificationError(
            f"channel {ch}: gap of {int(nearest[k]) - 1} samples after t = "
            f"{(stamps[k] - t0) / 1e9:.6g} s ({series.stamp_source}; {gaps.size} gaps in all)")
    return step


def align(series: Sequence[Series], max_jitter: float = DEFAULT_JITTER
          ) -> tuple[np.ndarray, np.ndarray, float]:
    """Common stamps [ns], values (N, len(series)) and step [s] of uniformly sampled channels.

    Every channel must have the same step (within ``max_jitter``); samples are matched to the
    first channel's stamps within ``max_jitter`` of a step on the span all channels cover.
    """
    steps = [_check_uniform(s, max_jitter) for s in series]
    ref = series[0]
    for s, step in zip(series, steps, strict=True):
        if abs(step - steps[0]) > max_jitter * steps[0]:
            raise IdentificationError(
                f"channels {ref.channel} and {s.channel} are sampled at different "
                             f"rates ({1e9 / steps[0]:.6g} Hz, {1e9 / step:.6g} Hz)")
    sorted_stamps = [np.sort(s.stamps_ns) for s in series]
    start = max(st[0] for st in sorted_stamps)
    stop = min(st[-1] for st in sorted_stamps)
    if stop <= start:
        raise IdentificationError("the channels' time spans do not overlap")
    step = steps[0]
    base = sorted_stamps[0]
    grid = base[(base >= start - max_jitter * step) & (base <= stop + max_jitter * step)]
    columns = []
    for s, st in zip(series, sorted_stamps, strict=True):
        vals = s.values[np.argsort(s.stamps_ns, kind="stable")]
        idx = np.clip(np.searchsorted(st, grid), 1, len(st) - 1)
        idx -= (grid - st[idx - 1]) < (st[idx] - grid)
        offset = np.abs(st[idx] - grid)
        bad = np.flatnonzero(offset > max_jitter * step)
        if bad.size:
            raise IdentificationError(
                f"channel {s.channel}: no sample within {max_jitter:.0%} of a step of "
                f"{ref.channel}'s sample at t = {(grid[bad[0]] - grid[0]) / 1e9:.6g} s "
                f"(offset {offset[bad[0]] / 1e6:.6g} ms)")
        columns.append(vals[idx])
    return grid, np.column_stack(columns), step / 1e9


def preprocess(data: np.ndarray, dt: float, *, detrend: bool = False,
               lowpass_hz: float | None = None, decimate: int = 1
               ) -> tuple[np.ndarray, float]:
    """Linear detrend, zero-phase low-pass (Butterworth, 4th order, forward-backward) and
    decimation (zero-phase FIR anti-alias filter) of the columns of ``data``."""
    nyquist = 0.5 / dt
    if detrend:
        data = signal.detrend(data, axis=0, type="linear")
    if lowpass_hz is not None:
        if not 0 < lowpass_hz < nyquist:
            raise InputError(f"--lowpass {lowpass_hz:g} Hz must lie between 0 and the Nyquist "
                             f"frequency {nyquist:g} Hz")
        sos = signal.butter(4, lowpass_hz, fs=1 / dt, output="sos")
        if len(data) <= 3 * 2 * len(sos):
            raise InputError(f"--lowpass: {len(data)} samples are too few to filter")
        data = signal.sosfiltfilt(sos, data, axis=0)
    if decimate < 1:
        raise InputError(f"--decimate {decimate}: must be a positive integer")
    if decimate > 1:
        if len(data) < 64 * decimate:
            raise InputError(f"--decimate {decimate}: {len(data)} samples are too few")
        data = signal.decimate(data, decimate, ftype="fir", axis=0, zero_phase=True)
        dt *= decimate
    return data, dt


def read_record(bag: str | Path, inputs: Sequence[Channel], outputs: Sequence[Channel], *,
                detrend: bool = False, lowpass_hz: float | None = None, decimate: int = 1,
                max_jitter: float = DEFAULT_JITTER, output_only: bool = False) -> Record:
    """Read, check, align and preprocess the input and output channels of a bag (no inputs with
    ``output_only``, which refuses any)."""
    if output_only and inputs:
        raise InputError("output-only identification takes no --input channel")
    if not inputs and not output_only:
        raise InputError("give at least one --input channel")
    if not outputs:
        raise InputError("give at least one --output channel")
    channels = [*inputs, *outputs]
    duplicates = sorted({str(c) for c in channels if channels.count(c) > 1})
    if duplicates:
        raise InputError(f"channel {duplicates[0]} is given twice")
    series = read_series(bag, channels)
    for s in series:
        if not np.all(np.isfinite(s.values)):
            k = int(np.flatnonzero(~np.isfinite(s.values))[0])
            raise IdentificationError(f"channel {s.channel}: non-finite value in sample {k}")
    stamps, data, dt = align(series, max_jitter)
    data, dt = preprocess(data, dt, detrend=detrend, lowpass_hz=lowpass_hz, decimate=decimate)
    m = len(inputs)
    return Record(
        bag=str(bag),
        inputs=tuple(s.channel for s in series[:m]),
        outputs=tuple(s.channel for s in series[m:]),
        t=np.arange(len(data)) * dt, u=data[:, :m], y=data[:, m:], dt=dt,
        start_ns=int(stamps[0]),
        preprocessing={"detrend": detrend, "lowpass_hz": lowpass_hz, "decimate": decimate,
                       "stamps": sorted({s.stamp_source for s in series})},
    )
