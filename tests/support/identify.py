"""A known 3-DOF shear frame, simulated exactly (ZOH), written to rosbag2 bags on the topic
contract's topics; shared by the identification tool's tests and nothing else."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from scipy import signal

TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MASSES = np.array([1.281, 0.814, 1.380])  # the thesis's rig (§5.2), README "Scenes"
STIFFNESSES = 24 * 207e9 * 2.917e-12 / np.array([0.23, 0.28, 0.23]) ** 3  # k_i = 24 E J / L_i^3
ALPHA, BETA = 0.5, 2e-4  # Rayleigh damping chosen positive for every mode
IMU_TOPICS = [f"/frame/floor{i}/imu" for i in (1, 2, 3)]
FORCE_TOPIC = "/frame/excitation/wrench"


def frame_matrices() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """M, K, C of the shear frame (force on floor 1)."""
    k = STIFFNESSES
    K = np.array([[k[0] + k[1], -k[1], 0], [-k[1], k[1] + k[2], -k[2]], [0, -k[2], k[2]]])
    M = np.diag(MASSES)
    return M, K, ALPHA * M + BETA * K


def true_modes() -> tuple[np.ndarray, np.ndarray]:
    """Natural frequencies [Hz] and damping ratios from the continuous eigenvalues."""
    M, K, C = frame_matrices()
    Minv = np.linalg.inv(M)
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-Minv @ K, -Minv @ C]])
    lam = np.linalg.eigvals(A)
    lam = lam[lam.imag > 0]
    lam = lam[np.argsort(np.abs(lam))]
    return np.abs(lam) / (2 * np.pi), -lam.real / np.abs(lam)


def discrete_model(dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """ZOH-sampled A, B, C, D from the floor-1 force to the three floor accelerations."""
    M, K, C = frame_matrices()
    Minv = np.linalg.inv(M)
    b = Minv @ np.array([1.0, 0.0, 0.0])
    A = np.block([[np.zeros((3, 3)), np.eye(3)], [-Minv @ K, -Minv @ C]])
    B = np.concatenate([np.zeros(3), b])[:, None]
    Cy = np.hstack([-Minv @ K, -Minv @ C])
    Ad, Bd, Cd, Dd, _ = signal.cont2discrete((A, B, Cy, b[:, None]), dt, method="zoh")
    return Ad, Bd, Cd, Dd


def simulate(samples: int, dt: float, seed: int = 0, noise: float = 0.0
             ) -> tuple[np.ndarray, np.ndarray]:
    """White-noise force on floor 1 (N) and the three floor accelerations (m/s^2), with
    Gaussian sensor noise of ``noise`` times each output's RMS."""
    rng = np.random.default_rng(seed)
    force = rng.standard_normal(samples)
    _, acc, _ = signal.dlsim((*discrete_model(dt), dt), force)
    if noise:
        acc = acc + noise * acc.std(axis=0) * rng.standard_normal(acc.shape)
    return force, acc


def _stamp(ns: int):
    return TYPESTORE.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)


def _header(ns: int):
    return TYPESTORE.types["std_msgs/msg/Header"](stamp=_stamp(ns), frame_id="frame")


def imu_message(ns: int, acc: float):
    T = TYPESTORE.types
    absent = np.zeros(9)
    absent[0] = -1.0
    return T["sensor_msgs/msg/Imu"](
        header=_header(ns), orientation=T["geometry_msgs/msg/Quaternion"](x=0, y=0, z=0, w=1),
        orientation_covariance=absent,
        angular_velocity=T["geometry_msgs/msg/Vector3"](x=0, y=0, z=0),
        angular_velocity_covariance=absent.copy(),
        linear_acceleration=T["geometry_msgs/msg/Vector3"](x=acc, y=0.0, z=0.0),
        linear_acceleration_covariance=np.diag([1e-6, 1e-6, 1e-6]).ravel())


def wrench_message(ns: int, force: float):
    T = TYPESTORE.types
    vec = T["geometry_msgs/msg/Vector3"]
    return T["geometry_msgs/msg/WrenchStamped"](
        header=_header(ns),
        wrench=T["geometry_msgs/msg/Wrench"](force=vec(x=force, y=0, z=0),
                                             torque=vec(x=0, y=0, z=0)))


def write_frame_bag(path: Path, force: np.ndarray, acc: np.ndarray, dt: float, *,
                    storage: StoragePlugin = StoragePlugin.MCAP,
                    stamp_edits: dict[str, dict[int, int | None]] | None = None,
                    start_ns: int = 1_700_000_000 * 10**9) -> Path:
    """Write force and accelerations as the simulator would. ``stamp_edits[topic][k]`` moves
    sample k's stamp by that many ns, or drops the sample when None."""
    edits = stamp_edits or {}
    stamps = start_ns + np.rint(np.arange(len(force)) * dt * 1e9).astype(np.int64)
    with Writer(path, version=9, storage_plugin=storage) as writer:
        conns = {t: writer.add_connection(t, "sensor_msgs/msg/Imu", typestore=TYPESTORE)
                 for t in IMU_TOPICS}
        conns[FORCE_TOPIC] = writer.add_connection(
            FORCE_TOPIC, "geometry_msgs/msg/WrenchStamped", typestore=TYPESTORE)
        for k, ns in enumerate(stamps):
            for topic, conn in conns.items():
                shift = edits.get(topic, {}).get(k, 0)
                if shift is None:
                    continue
                stamp = int(ns) + shift
                if topic == FORCE_TOPIC:
                    msg = wrench_message(stamp, float(force[k]))
                else:
                    msg = imu_message(stamp, float(acc[k, IMU_TOPICS.index(topic)]))
                writer.write(conn, stamp + 200_000, TYPESTORE.serialize_cdr(msg, conn.msgtype))
    return path
