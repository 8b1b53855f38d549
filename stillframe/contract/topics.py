"""The topic contract (docs/architecture.md, "Topic contract") as data, for nodes, tools and tests.

Names are relative to the node namespace (default ``/frame``) unless absolute. All units SI,
angles in rad; stamps are the sample time of the measurement (sim time with ``use_sim_time``).
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["CLOCK", "CONDITIONAL", "CONTRACT", "DEFAULT_NAMESPACE", "DIAGNOSTICS", "ENERGY_BALANCE",
           "ENERGY_FIELDS", "EXCITATION_WRENCH", "FLOOR3_LOAD_CELL", "FLOOR_IMU", "FORCE_CMD",
           "PENDULUM_JOINT_STATES", "PER_SAMPLE", "STATE_COVARIANCE", "STATE_ESTIMATE",
           "STATE_TRUTH", "STATUS_KEYS", "STRUCTURE_EVENTS", "TORQUE_CMD", "TopicSpec"]

DEFAULT_NAMESPACE = "/frame"


@dataclass(frozen=True)
class TopicSpec:
    """One row of the contract: name, message type, QoS profile name, what it carries, and
    ``field``, the message field that carries its scalar quantity (a dotted path with ``[i]``
    for array elements; empty where the message carries several). :mod:`~.codecs` writes and
    reads those fields; :mod:`stillframe.bags.channels` reads them by default."""

    name: str
    type_name: str
    qos: str
    content: str
    field: str = ""


CLOCK = TopicSpec(
    "/clock", "rosgraph_msgs/msg/Clock", "clock", "sim time, published by the simulator"
)
FLOOR_IMU = tuple(
    TopicSpec(
        f"floor{n}/imu", "sensor_msgs/msg/Imu", "sensor_data",
        f"linear_acceleration.x = floor {n} horizontal acceleration; covariances filled; "
        "orientation and angular velocity absent (covariance[0] = -1)",
        "linear_acceleration.x",
    )
    for n in (1, 2, 3)
)
PENDULUM_JOINT_STATES = TopicSpec(
    "pendulum/joint_states", "sensor_msgs/msg/JointState", "sensor_data",
    "encoder: name 'pendulum', position = phi; effort = hinge torque the motor applied over the "
    "previous sample period (after saturation and slew limits)", "position[0]",
)
EXCITATION_WRENCH = TopicSpec(
    "excitation/wrench", "geometry_msgs/msg/WrenchStamped", "sensor_data",
    "load cell on the excited floor: force.x", "wrench.force.x",
)
FLOOR3_LOAD_CELL = TopicSpec(
    "floor3/load_cell", "geometry_msgs/msg/WrenchStamped", "sensor_data",
    "load cell of the floor-3 actuator: force.x = force applied over the previous sample period "
    "(after saturation and slew limits)", "wrench.force.x",
)
TORQUE_CMD = TopicSpec(
    "pendulum/torque_cmd", "geometry_msgs/msg/WrenchStamped", "default",
    "command torque on the pendulum hinge: torque.z; stamp = stamp of the estimate used",
    "wrench.torque.z",
)
FORCE_CMD = TopicSpec(
    "floor3/force_cmd", "geometry_msgs/msg/WrenchStamped", "default",
    "command force on floor 3 (EUK variant 2): force.x", "wrench.force.x",
)
STATE_ESTIMATE = TopicSpec(
    "state_estimate", "sensor_msgs/msg/JointState", "default",
    "names x1 x2 x3 phi, position and velocity; effort: the actuation taken as applied over "
    "the previous period (floor-3 force on x3, pendulum torque on phi, 0 on x1 x2)",
)
STATE_COVARIANCE = TopicSpec(
    "state_estimate/covariance", "std_msgs/msg/Float64MultiArray", "default",
    "8x8 row-major covariance of [q, qdot]",
)
STATE_TRUTH = TopicSpec(
    "state_truth", "sensor_msgs/msg/JointState", "default",
    "simulator ground truth, same names as state_estimate",
)
DIAGNOSTICS = TopicSpec(
    "/diagnostics", "diagnostic_msgs/msg/DiagnosticArray", "default",
    "per node: loop rate, latency, deadline misses, rejected messages, saturation",
)

#: ``energy_balance``'s ``data``, in this order (also its ``layout.dim[0].label``, comma-joined)
ENERGY_FIELDS: tuple[str, ...] = ("t_s", "stored_J", "excitation_W", "actuator_W", "noise_W",
                                  "dissipated_W")
ENERGY_BALANCE = TopicSpec(
    "energy_balance", "std_msgs/msg/Float64MultiArray", "default",
    "pH plant (model.type: ph) only, one per sample: data = [t_k (s), H(t_k) above rest (J), "
    "mean power over the period just ended supplied through the excitation, actuator and "
    "process-noise ports (W), mean dissipated power (W)]; layout.dim[0]: label = the field names "
    "comma-joined, size = stride = 6. T·(P_excitation + P_actuator + P_noise − P_dissipated) of "
    "sample k equals H(t_k) − H(t_k−1) to round-off; powers are 0 at t = 0",
    "data[1]",
)

STRUCTURE_EVENTS = TopicSpec(
    "structure_events", "diagnostic_msgs/msg/DiagnosticArray", "default",
    "scenes with events only: one message at each sample where the simulator changed the "
    "plant's structure, stamped with that sample's time; a status per event applied (name "
    "'<node>: events[i]', level OK, message a one-line summary) with the values event, "
    "time_s (the event's time), applied_s, sample and each scene key it changed with its "
    "value after it, as JSON (stillframe.contract.structure_events)",
)

ADAPTATION_EVENTS = TopicSpec(
    "adaptation/events", "diagnostic_msgs/msg/DiagnosticArray", "default",
    "scenes with adaptation.enabled only, from estimator_node: one message per event of the "
    "adaptation, stamped with the sample that decided it; one status (name '<node>: "
    "adaptation <kind>', level WARN for a detection or a refusal, OK for a design, message a "
    "one-line summary) whose values are the event's record as JSON: kind (detection, design, "
    "refusal), t (the deciding sample's time), and for a detection onset_s, mode, statistic, "
    "reference_hz, frequency_hz; for a design handover_s, identified_hz, design_hz, the storeys' "
    "mass and stiffness, the gain and the poles (stillframe.contract.adaptation_events)",
)

CONTRACT: tuple[TopicSpec, ...] = (
    CLOCK, *FLOOR_IMU, PENDULUM_JOINT_STATES, EXCITATION_WRENCH, FLOOR3_LOAD_CELL, TORQUE_CMD,
    FORCE_CMD,
    STATE_ESTIMATE, STATE_COVARIANCE, STATE_TRUTH, DIAGNOSTICS,
)
#: the topics the simulator publishes once per sample, by absolute name (in the default
#: namespace): a run of N samples sends N messages on each
PER_SAMPLE: tuple[str, ...] = tuple(
    spec.name if spec.name.startswith("/") else f"{DEFAULT_NAMESPACE}/{spec.name}"
    for spec in (CLOCK, *FLOOR_IMU, PENDULUM_JOINT_STATES, EXCITATION_WRENCH, FLOOR3_LOAD_CELL,
                 STATE_TRUTH))
#: topics a loop node publishes only for some scenes (not every launch has them)
CONDITIONAL: tuple[TopicSpec, ...] = (ENERGY_BALANCE, STRUCTURE_EVENTS, ADAPTATION_EVENTS)


#: the ``/diagnostics`` values the status line shows, when a node reports them
STATUS_KEYS: tuple[str, ...] = ("sim_time_s", "step", "realtime_factor", "deadline_misses",
                                "overruns", "rejected", "partial_updates", "saturated",
                                "watchdog", "passivity_violations")
