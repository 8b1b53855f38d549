"""stillframe.bags.channels: channels from real rosbag2 files, alignment, refusals,
preprocessing."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from scipy import signal

from stillframe.bags.channels import Channel, align, preprocess, read_record, read_series
from stillframe.errors import IdentificationError, InputError
from tests.support.identify import FORCE_TOPIC, IMU_TOPICS, TYPESTORE, simulate, write_frame_bag

DT = 1 / 32
INPUTS = [Channel.parse(FORCE_TOPIC)]
OUTPUTS = [Channel.parse(t) for t in IMU_TOPICS]


@pytest.mark.parametrize("storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3])
def test_values_come_back_exactly(tmp_path: Path, storage: StoragePlugin) -> None:
    force, acc = simulate(300, DT, seed=0)
    bag = write_frame_bag(tmp_path / "bag", force, acc, DT, storage=storage)
    record = read_record(bag, INPUTS, OUTPUTS)
    assert record.dt == pytest.approx(DT, rel=1e-9)
    np.testing.assert_array_equal(record.u[:, 0], force)
    np.testing.assert_array_equal(record.y, acc)
    assert record.inputs[0].field == "wrench.force.x"
    assert record.preprocessing["stamps"] == ["header"]


def test_channels_are_aligned_on_their_common_span(tmp_path: Path) -> None:
    """Floor 1's IMU starts 10 samples late: the record starts there, sample for sample."""
    force, acc = simulate(300, DT, seed=1)
    late = {IMU_TOPICS[0]: {k: None for k in range(10)}}
    bag = write_frame_bag(tmp_path / "bag", force, acc, DT, stamp_edits=late)
    record = read_record(bag, INPUTS, OUTPUTS)
    assert record.samples == 290
    np.testing.assert_array_equal(record.u[:, 0], force[10:])
    np.testing.assert_array_equal(record.y, acc[10:])


def test_a_channel_offset_by_half_a_step_is_refused(tmp_path: Path) -> None:
    force, acc = simulate(100, DT, seed=2)
    half = int(DT * 1e9 / 2)
    bag = write_frame_bag(tmp_path / "bag", force, acc, DT,
                          stamp_edits={IMU_TOPICS[2]: dict.fromkeys(range(100), half)})
    with pytest.raises(IdentificationError, match="no sample within 5% of a step"):
        read_record(bag, INPUTS, OUTPUTS)


def test_log_time_is_used_without_a_header(tmp_path: Path) -> None:
    """std_msgs/Float64 has no header: samples sit at their log times (default field data)."""
    path = tmp_path / "bag"
    values = np.sin(np.arange(50) * 0.3)
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/x", "std_msgs/msg/Float64", typestore=TYPESTORE)
        for k, v in enumerate(values):
            msg = TYPESTORE.types["std_msgs/msg/Float64"](data=float(v))
            writer.write(conn, 10**9 + k * 20_000_000,
                         TYPESTORE.serialize_cdr(msg, "std_msgs/msg/Float64"))
    (series,) = read_series(path, [Channel.parse("/x")])
    assert series.stamp_source == "log time" and series.channel.field == "data"
    np.testing.assert_array_equal(series.values, values)
    stamps, data, dt = align([series])
    assert len(stamps) == 50 and np.array_equal(data[:, 0], values)
    assert dt == pytest.approx(0.02)


def test_different_rates_are_refused(tmp_path: Path) -> None:
    force, acc = simulate(200, DT, seed=3)
    every_other = {IMU_TOPICS[1]: {k: None for k in range(1, 200, 2)}}
    bag = write_frame_bag(tmp_path / "bag", force, acc, DT, stamp_edits=every_other)
    with pytest.raises(IdentificationError, match=r"different rates \(32 Hz, 16 Hz\)"):
        read_record(bag, INPUTS, OUTPUTS)


def test_repeated_channel_and_bad_specs_are_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="must be absolute"):
        Channel.parse("frame/floor1/imu")
    with pytest.raises(InputError, match="bad field path"):
        Channel.parse("/frame/floor1/imu:linear_acceleration..x")
    with pytest.raises(InputError, match="given twice"):
        read_record(tmp_path, INPUTS, [*OUTPUTS, OUTPUTS[0]])


def test_out_of_range_index_is_refused(tmp_path: Path) -> None:
    force, acc = simulate(50, DT, seed=4)
    bag = write_frame_bag(tmp_path / "bag", force, acc, DT)
    with pytest.raises(InputError, match=r"linear_acceleration_covariance\[9\] is out of range"):
        read_record(bag, INPUTS, [Channel.parse(f"{IMU_TOPICS[0]}:"
                                                "linear_acceleration_covariance[9]")])


def test_lowpass_is_zero_phase_and_decimation_keeps_the_passband() -> None:
    """1 Hz + 12 Hz at 64 Hz; a 4 Hz low-pass leaves the 1 Hz sine unshifted, and decimating
    by 4 (16 Hz) keeps it too. Compared inside the record, away from the filters' edges."""
    dt = 1 / 64
    t = np.arange(4096) * dt
    slow = np.sin(2 * np.pi * 1.0 * t)
    data = np.column_stack([slow + 0.5 * np.sin(2 * np.pi * 12.0 * t), 3 * slow])
    filtered, dt1 = preprocess(data, dt, lowpass_hz=4.0)
    inner = slice(200, -200)
    assert dt1 == dt
    np.testing.assert_allclose(filtered[inner, 0], slow[inner], atol=2e-3)
    decimated, dt4 = preprocess(data, dt, lowpass_hz=4.0, decimate=4)
    assert dt4 == pytest.approx(4 * dt)
    np.testing.assert_allclose(decimated[50:-50, 1], 3 * slow[::4][50:-50], atol=1e-2)
    detrended, _ = preprocess(data + np.array([5.0, -2.0]) + 0.1 * t[:, None], dt, detrend=True)
    np.testing.assert_allclose(detrended, signal.detrend(data, axis=0), atol=1e-9)


def test_preprocessing_limits_are_refused() -> None:
    data = np.zeros((1000, 2))
    with pytest.raises(InputError, match="Nyquist frequency 16 Hz"):
        preprocess(data, DT, lowpass_hz=20.0)
    with pytest.raises(InputError, match="--decimate 0"):
        preprocess(data, DT, decimate=0)


def test_one_topic_on_two_connections_is_merged(tmp_path: Path) -> None:
    """A topic recorded from two connections (two publishers, or two QoS offers in a
    ``ros2 bag record`` MCAP): samples are merged by stamp."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    from tests.support.identify import imu_message

    def qos(reliability: QosReliability) -> Qos:
        never = QosTime(0, 0)
        return Qos(QosHistory.KEEP_LAST, 5, reliability, QosDurability.VOLATILE, never, never,
                   QosLiveliness.AUTOMATIC, never, False)

    values = np.cos(np.arange(40) * 0.2)
    path = tmp_path / "bag"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = [writer.add_connection("/frame/floor1/imu", "sensor_msgs/msg/Imu",
                                       typestore=TYPESTORE, offered_qos_profiles=[qos(rel)])
                 for rel in (QosReliability.BEST_EFFORT, QosReliability.RELIABLE)]
        for k, v in enumerate(values):
            ns = 10**9 + k * 10_000_000
            writer.write(conns[k % 2], ns, TYPESTORE.serialize_cdr(imu_message(ns, float(v)),
                                                                   "sensor_msgs/msg/Imu"))
    (series,) = read_series(path, [Channel.parse("/frame/floor1/imu")])
    np.testing.assert_array_equal(series.values, values)
