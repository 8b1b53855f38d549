"""The loop's signals on the wire: :mod:`stillframe.contract.signals` ↔ the contract's ROS messages
(docs/architecture.md "Topic contract", :mod:`stillframe.contract.topics`).

Each writer keeps one message instance per topic and refills it every sample (no per-step
construction); its ``cdr`` method writes the same bytes straight into preallocated buffers
(:mod:`~.fixed_cdr`), the nodes' hot path, and the ``*_reader`` functions read them back.
Stamps are integer nanoseconds; :class:`SampleGrid` turns them back into the exact float
sample times ``k · period`` the one-process loop uses, so that the nodes compute bit-for-bit
what :func:`stillframe.loop.closed_loop.run_closed_loop` computes.
"""

from __future__ import annotations

import struct
from typing import Any

import numpy as np

from stillframe.config.loop_sections import Sensors
from stillframe.contract import messages, topics
from stillframe.contract.fixed_cdr import FixedReader, FixedWriter
from stillframe.contract.signals import Command, Estimate, Sample

STATE_NAMES = ["x1", "x2", "x3", "phi"]
#: the header stamp's fields, first in every stamped message
STAMP = ("header.stamp.sec", "header.stamp.nanosec")
PENDULUM_JOINT = "pendulum"
#: The sensor topics in the order of their readings [a1, a2, a3, φ, load cell]
#: (``Sample.present``): a topic's index is its channel.
SENSOR_TOPICS = (*topics.FLOOR_IMU, topics.PENDULUM_JOINT_STATES, topics.EXCITATION_WRENCH)
ENCODER_CHANNEL = SENSOR_TOPICS.index(topics.PENDULUM_JOINT_STATES)
#: What the simulator publishes per sample besides the truth, in the order of
#: :meth:`SensorMessages.fill`: the sensor topics and the floor-3 actuator's load cell.
SAMPLE_TOPICS = (*SENSOR_TOPICS, topics.FLOOR3_LOAD_CELL)
#: Command topics in the order of ``Command.vector`` = [pendulum torque, floor-3 force].
COMMAND_TOPICS = (topics.TORQUE_CMD, topics.FORCE_CMD)


#: what joins a stamped message's frame and the run's token in ``header.frame_id``
TOKEN_MARK = "#"
#: the offset of ``header.frame_id``'s length in a stamped message's CDR: the 4-byte
#: encapsulation, then the stamp's ``sec`` and ``nanosec``
FRAME_ID_AT = 12


def stamped_frame(frame: str, token: str) -> str:
    """The ``header.frame_id`` a loop node writes: the frame, and the run's token after
    :data:`TOKEN_MARK` when the run has one (``floor1#3f9a0c2e5b7d1a64``; docs/nodes.md, writer
    identity)."""
    return f"{frame}{TOKEN_MARK}{token}" if token else frame


def token_suffix(token: str) -> bytes:
    """The bytes every ``frame_id`` of the run ends with (empty without a token)."""
    return (TOKEN_MARK + token).encode() if token else b""


_FRAME_ID_LENGTH = struct.Struct("<I").unpack_from


def carries_token(data: bytes | memoryview, suffix: bytes) -> bool:
    """Whether the CDR ``data`` of a stamped message (little-endian, as the loop's nodes write
    it) has a ``header.frame_id`` ending in ``suffix``: a length read and one slice compared,
    before anything is decoded (a slice past the end is short, so never equal)."""
    try:
        length = _FRAME_ID_LENGTH(data, FRAME_ID_AT)[0]     # the string's, with its NUL
    except struct.error:                                    # too short for a header
        return False
    end = FRAME_ID_AT + 3 + length
    return data[1] == 1 and length > len(suffix) and data[end - len(suffix):end] == suffix


class SampleGrid:
    """Sample times k·period ↔ stamps in ns; a stamp within 1 µs of the grid reads back as the
    exact grid time (what the simulator computed), any other as ``ns · 1e-9``."""

    def __init__(self, period: float) -> None:
        self.period = period

    @staticmethod
    def ns(t: float) -> int:
        """``t`` [s] as integer nanoseconds, rounded (the stamp of a sample time)."""
        return round(t * 1e9)

    def index(self, ns: int) -> int:
        """The sample k nearest to stamp ``ns``."""
        return round(ns * 1e-9 / self.period)

    def seconds(self, ns: int) -> float:
        """The sample time [s] of the stamp ``ns``: k × period when ``ns`` lies within 1 µs of the
        grid (so a stamp gives back the exact float the simulator used), else ``ns`` × 1e-9."""
        t = self.index(ns) * self.period
        return t if abs(round(t * 1e9) - ns) <= 1000 else ns * 1e-9


def set_stamp(msg: Any, ns: int) -> None:
    """Set ``msg.header.stamp`` to ``ns`` nanoseconds in place."""
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)


def _joint_state(names: list[str]) -> Any:
    return messages.new("sensor_msgs/msg/JointState", name=names)


def fill_joint_state(msg: Any, ns: int, physical: np.ndarray) -> None:
    """x1 x2 x3 phi positions and velocities from [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇]."""
    set_stamp(msg, ns)
    msg.position = np.asarray(physical[:4], dtype=np.float64)
    msg.velocity = np.asarray(physical[4:8], dtype=np.float64)


class SensorMessages:
    """The rig's sensor messages for one :class:`Sample`: floor IMUs, encoder, load cell, and
    the ground truth (``state_truth``); covariances from the scene's ``sensors`` section; every
    ``frame_id`` with the run's ``token`` (:func:`stamped_frame`)."""

    def __init__(self, sensors: Sensors, token: str = "") -> None:
        var_a = float(sensors.accelerometer_noise_std) ** 2
        self.imus = []
        for n in (1, 2, 3):
            imu = messages.new("sensor_msgs/msg/Imu")
            imu.header.frame_id = stamped_frame(f"floor{n}", token)
            imu.orientation_covariance[0] = -1.0      # not measured
            imu.angular_velocity_covariance[0] = -1.0
            imu.linear_acceleration_covariance[0] = var_a
            self.imus.append(imu)
        self.encoder = _joint_state([PENDULUM_JOINT])
        self.encoder.header.frame_id = stamped_frame("pendulum", token)
        self.encoder.position, self.encoder.effort = np.zeros(1), np.zeros(1)
        self.load_cell = messages.new("geometry_msgs/msg/WrenchStamped")
        self.load_cell.header.frame_id = stamped_frame("floor1", token)
        self.actuator_load_cell = messages.new("geometry_msgs/msg/WrenchStamped")
        self.actuator_load_cell.header.frame_id = stamped_frame("floor3", token)
        self.truth = _state_message(token)
        self._imu_cdr = [FixedWriter(imu, (*STAMP, "linear_acceleration.x"))
                         for imu in self.imus]
        self._encoder_cdr = FixedWriter(self.encoder, (*STAMP, "position", "effort"))
        self._wrench_cdr = [FixedWriter(m, (*STAMP, "wrench.force.x"))
                            for m in (self.load_cell, self.actuator_load_cell)]
        self._truth_cdr = FixedWriter(self.truth, (*STAMP, "position", "velocity"))

    def fill(self, sample: Sample, ns: int) -> list[Any]:
        """[imu1, imu2, imu3, encoder, load cell, floor-3 load cell] for ``sample``, stamped
        ``ns``; the encoder's effort and the floor-3 load cell carry ``sample.applied``."""
        for imu, a in zip(self.imus, sample.measurements[:3], strict=True):
            set_stamp(imu, ns)
            imu.linear_acceleration.x = float(a)
        set_stamp(self.encoder, ns)
        self.encoder.position = np.array([sample.measurements[3]])
        applied = np.zeros(2) if sample.applied is None else sample.applied
        self.encoder.effort = np.array([applied[0]])
        set_stamp(self.load_cell, ns)
        self.load_cell.wrench.force.x = float(sample.force)
        set_stamp(self.actuator_load_cell, ns)
        self.actuator_load_cell.wrench.force.x = float(applied[1])
        return [*self.imus, self.encoder, self.load_cell, self.actuator_load_cell]

    def fill_truth(self, sample: Sample, ns: int) -> Any:
        """The ``state_truth`` message filled in place with the sample's true state, stamped
        ``ns``."""
        fill_joint_state(self.truth, ns, sample.truth)
        return self.truth

    def cdr(self, sample: Sample, ns: int) -> list[bytearray]:
        """The CDR of :meth:`fill` and then :meth:`fill_truth` (the same bytes), written into
        preallocated buffers that the next call rewrites."""
        sec, nanosec = divmod(ns, 1_000_000_000)
        m = sample.measurements
        applied = (0.0, 0.0) if sample.applied is None else sample.applied
        out = [w.pack(sec, nanosec, float(a)) for w, a in zip(self._imu_cdr, m[:3], strict=True)]
        out.append(self._encoder_cdr.pack(sec, nanosec, float(m[3]), float(applied[0])))
        out.append(self._wrench_cdr[0].pack(sec, nanosec, float(sample.force)))
        out.append(self._wrench_cdr[1].pack(sec, nanosec, float(applied[1])))
        out.append(self._truth_cdr.pack(sec, nanosec, *sample.truth[:8].tolist()))
        return out


def sensor_reading(channel: int, msg: Any) -> float:
    """The reading of sensor channel ``channel`` (index in :data:`SENSOR_TOPICS`) in ``msg``;
    NaN when the encoder message carries no ``pendulum`` position."""
    if channel < 3:
        return float(msg.linear_acceleration.x)
    if channel == 4:
        return float(msg.wrench.force.x)
    names = list(msg.name)
    if names and PENDULUM_JOINT not in names:
        return float("nan")
    i = names.index(PENDULUM_JOINT) if names else 0
    return float(msg.position[i]) if i < len(msg.position) else float("nan")


def applied_torque(msg: Any) -> float:
    """The hinge torque applied over the previous period, the ``effort`` of the encoder
    message's ``pendulum`` joint; NaN when it carries none."""
    names = list(msg.name)
    if names and PENDULUM_JOINT not in names:
        return float("nan")
    i = names.index(PENDULUM_JOINT) if names else 0
    return float(msg.effort[i]) if i < len(msg.effort) else float("nan")


def physical_state(msg: Any) -> np.ndarray:
    """[x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇] of a ``state_estimate``/``state_truth`` JointState,
    ordered by joint name; NaN where a name or value is missing."""
    out = np.full(8, np.nan)
    names = list(msg.name)
    for i, name in enumerate(STATE_NAMES):
        if name in names:
            j = names.index(name)
            if j < len(msg.position):
                out[i] = msg.position[j]
            if j < len(msg.velocity):
                out[4 + i] = msg.velocity[j]
    return out


def _state_message(token: str) -> Any:
    """A ``state_truth``/``state_estimate`` JointState of the run with ``token``: x1 x2 x3 phi,
    4 positions and 4 velocities."""
    msg = _joint_state(list(STATE_NAMES))
    msg.header.frame_id = stamped_frame("", token)
    msg.position, msg.velocity = np.zeros(4), np.zeros(4)
    return msg


def estimate_efforts(applied: np.ndarray | None) -> np.ndarray:
    """``state_estimate``'s ``effort`` for x1 x2 x3 phi from the actuation applied, [torque,
    force]: the floor-3 force on x3, the torque on φ, 0 on x1 and x2 (NaN where not known)."""
    torque, force = (np.nan, np.nan) if applied is None else applied
    return np.array([0.0, 0.0, force, torque])


def applied_of(efforts: Any) -> np.ndarray:
    """[torque, force] from ``state_estimate``'s ``effort`` (:func:`estimate_efforts`); NaN
    where a writer gave none."""
    return (np.array([efforts[3], efforts[2]], dtype=float) if len(efforts) >= 4
            else np.full(2, np.nan))


class EstimateMessages:
    """``state_estimate`` (its ``frame_id`` the run's ``token``; its ``effort`` the actuation the
    estimator took as applied over the period before the stamp, :func:`estimate_efforts`) and its
    8×8 covariance (zeros for the exact ``truth`` estimator; a ``Float64MultiArray`` has no
    header)."""

    def __init__(self, token: str = "") -> None:
        self.state = _state_message(token)
        self.state.effort = np.zeros(4)
        dims = [messages.new("std_msgs/msg/MultiArrayDimension", label=label, size=8,
                             stride=stride) for label, stride in (("rows", 64), ("cols", 8))]
        self.covariance = messages.new("std_msgs/msg/Float64MultiArray")
        self.covariance.layout.dim = dims
        self.covariance.data = np.zeros(64)
        self._state_cdr = FixedWriter(self.state, (*STAMP, "position", "velocity", "effort"))
        self._cov_cdr = FixedWriter(self.covariance, ("data",))

    def fill(self, estimate: Estimate, ns: int) -> tuple[Any, Any]:
        """The ``state_estimate`` and its covariance message filled in place (zeros for an estimator
        without a covariance), stamped ``ns``."""
        fill_joint_state(self.state, ns, estimate.physical)
        self.state.effort = estimate_efforts(estimate.applied)
        cov = np.zeros((8, 8)) if estimate.covariance is None else estimate.covariance
        self.covariance.data = np.ascontiguousarray(cov, dtype=np.float64).ravel()
        return self.state, self.covariance

    def cdr(self, estimate: Estimate, ns: int) -> tuple[bytearray, bytearray]:
        """The CDR of :meth:`fill`, in preallocated buffers that the next call rewrites."""
        sec, nanosec = divmod(ns, 1_000_000_000)
        state = self._state_cdr.pack(sec, nanosec, *estimate.physical[:8].tolist(),
                                     *estimate_efforts(estimate.applied).tolist())
        cov = (np.zeros(64) if estimate.covariance is None
               else np.asarray(estimate.covariance, dtype=np.float64).ravel())
        return state, self._cov_cdr.pack(*cov.tolist())


class EnergyMessage:
    """``energy_balance`` (:data:`~stillframe.contract.topics.ENERGY_BALANCE`): the pH plant's
    stored energy and port powers of one sample."""

    def __init__(self) -> None:
        n = len(topics.ENERGY_FIELDS)
        self.msg = messages.new("std_msgs/msg/Float64MultiArray")
        self.msg.layout.dim = [messages.new("std_msgs/msg/MultiArrayDimension",
                                            label=",".join(topics.ENERGY_FIELDS), size=n,
                                            stride=n)]
        self.msg.data = np.zeros(n)
        self._cdr = FixedWriter(self.msg, ("data",))

    def cdr(self, t: float, balance: np.ndarray) -> bytearray:
        """The CDR of [t, *balance] in a preallocated buffer the next call rewrites."""
        return self._cdr.pack(t, *np.asarray(balance, dtype=np.float64).tolist())


def energy_values(msg: Any) -> dict[str, float]:
    """An ``energy_balance`` message as {field: value} (:data:`topics.ENERGY_FIELDS`)."""
    return dict(zip(topics.ENERGY_FIELDS, (float(v) for v in msg.data), strict=True))


class CommandMessage:
    """The command on its topic: ``torque.z`` (pendulum) or ``force.x`` (floor 3), its
    ``frame_id`` with the run's ``token``."""

    def __init__(self, actuator: int, token: str = "") -> None:
        self.actuator = actuator
        self.msg = messages.new("geometry_msgs/msg/WrenchStamped")
        self.msg.header.frame_id = stamped_frame("pendulum" if actuator == 0 else "floor3", token)
        self.field = "wrench.torque.z" if actuator == 0 else "wrench.force.x"
        self._cdr = FixedWriter(self.msg, (*STAMP, self.field))

    def fill(self, command: Command, ns: int) -> Any:
        """The command message filled in place: ``torque.z`` for the pendulum, ``force.x`` for the
        floor-3 actuator, stamped ``ns``."""
        set_stamp(self.msg, ns)
        if self.actuator == 0:
            self.msg.wrench.torque.z = command.torque
        else:
            self.msg.wrench.force.x = command.force
        return self.msg

    def cdr(self, command: Command, ns: int) -> bytearray:
        """The CDR of :meth:`fill`, in a preallocated buffer that the next call rewrites."""
        value = command.torque if self.actuator == 0 else command.force
        return self._cdr.pack(*divmod(ns, 1_000_000_000), float(value))


def command_value(actuator: int, msg: Any) -> float:
    """The commanded torque (actuator 0) or floor-3 force (1) in a WrenchStamped."""
    return float(msg.wrench.torque.z if actuator == 0 else msg.wrench.force.x)


class TopicReader:
    """The values a node takes from one contract topic's CDR: read straight from the bytes when
    they have the layout the stack's own writers give (:class:`~.fixed_cdr.FixedReader`), else
    decoded with ``rosbags``; both give the same tuple. None for bytes that are no valid message
    of the type (the caller counts them as malformed)."""

    def __init__(self, template: Any, paths: tuple[str, ...],
                 from_values: Any, from_msg: Any) -> None:
        self.type_name = template.__msgtype__
        self._fixed = FixedReader(template, paths)
        self._from_values = from_values
        self._from_msg = from_msg

    def read(self, data: bytes | memoryview) -> tuple[Any, ...] | None:
        """The values of one sample's CDR ``data``: by the fixed layout when it matches, else
        decoded with ``rosbags``; None for a malformed sample."""
        values = self._fixed.unpack(data)
        if values is not None:
            return self._from_values(values)
        msg = messages.decode_sample(data, self.type_name)
        return None if msg is None else self._from_msg(msg)


def _stamped(v: tuple[Any, ...]) -> tuple[Any, ...]:
    """(ns, values...) of (sec, nanosec, values...)."""
    return (v[0] * 1_000_000_000 + v[1], *v[2:])


def sensor_reader(channel: int, sensors: Sensors, token: str = "") -> TopicReader:
    """(stamp ns, reading, applied torque or NaN) of sensor channel ``channel``
    (:func:`sensor_reading`, :func:`applied_torque`), read in place from the layout the
    simulator of the run with ``token`` writes."""
    out = SensorMessages(sensors, token)
    template = [*out.imus, out.encoder, out.load_cell][channel]
    field = {3: ("position", "effort"), 4: ("wrench.force.x",)}.get(
        channel, ("linear_acceleration.x",))
    nan = float("nan")

    def from_msg(msg: Any) -> tuple[Any, ...]:
        torque = applied_torque(msg) if channel == ENCODER_CHANNEL else nan
        return messages.stamp_ns(msg.header.stamp), sensor_reading(channel, msg), torque

    def from_values(v: tuple[Any, ...]) -> tuple[Any, ...]:
        return _stamped(v) if channel == ENCODER_CHANNEL else (*_stamped(v), nan)

    return TopicReader(template, (*STAMP, *field), from_values, from_msg)


def wrench_reader(frame: str, field: str, token: str = "") -> TopicReader:
    """(stamp ns, ``field``) of a WrenchStamped (load cells, commands) in ``frame``."""
    template = messages.new("geometry_msgs/msg/WrenchStamped")
    template.header.frame_id = stamped_frame(frame, token)
    parts = field.split(".")

    def from_msg(msg: Any) -> tuple[Any, ...]:
        value = msg
        for part in parts:
            value = getattr(value, part)
        return messages.stamp_ns(msg.header.stamp), float(value)

    return TopicReader(template, (*STAMP, field), _stamped, from_msg)


def state_reader(token: str = "") -> TopicReader:
    """(stamp ns, [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇]) of ``state_truth`` (:func:`physical_state`),
    read in place from the layout the simulator writes."""
    def from_values(v: tuple[Any, ...]) -> tuple[Any, ...]:
        return v[0] * 1_000_000_000 + v[1], np.array(v[2:])

    def from_msg(msg: Any) -> tuple[Any, ...]:
        return messages.stamp_ns(msg.header.stamp), physical_state(msg)

    return TopicReader(_state_message(token), (*STAMP, "position", "velocity"), from_values,
                       from_msg)


def estimate_reader(token: str = "") -> TopicReader:
    """(stamp ns, [x1, x2, x3, φ, ẋ1, ẋ2, ẋ3, φ̇], [torque, force] applied) of
    ``state_estimate`` (:func:`physical_state`, :func:`applied_of`), read in place from the
    layout the estimator writes."""
    def from_values(v: tuple[Any, ...]) -> tuple[Any, ...]:
        return v[0] * 1_000_000_000 + v[1], np.array(v[2:10]), applied_of(v[10:14])

    def from_msg(msg: Any) -> tuple[Any, ...]:
        ordered = list(msg.name) == list(STATE_NAMES)
        return (messages.stamp_ns(msg.header.stamp), physical_state(msg),
                applied_of(msg.effort if ordered else ()))

    return TopicReader(EstimateMessages(token).state, (*STAMP, "position", "velocity", "effort"),
                       from_values, from_msg)


def command_reader(actuator: int, token: str = "") -> TopicReader:
    """(stamp ns, command value) of a command topic (:func:`command_value`)."""
    def from_msg(msg: Any) -> tuple[Any, ...]:
        return messages.stamp_ns(msg.header.stamp), command_value(actuator, msg)

    out = CommandMessage(actuator, token)
    return TopicReader(out.msg, (*STAMP, out.field), _stamped, from_msg)


def clock_reader() -> TopicReader:
    """(sim time ns,) of ``/clock``."""
    def from_msg(msg: Any) -> tuple[Any, ...]:
        return (messages.stamp_ns(msg.clock),)

    return TopicReader(messages.new(topics.CLOCK.type_name), ("clock.sec", "clock.nanosec"),
                       _stamped, from_msg)
