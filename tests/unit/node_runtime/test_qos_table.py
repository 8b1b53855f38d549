"""The QoS table of docs/nodes.md is the code's: generated from the topic contract and
``LoopParameters.qos``/``reader_qos``, and the page holds exactly that table (issue 26: two pages
said different things). The table's lock-step sensor rows against the rule stated in the docs."""

from __future__ import annotations

from stillframe.locations import REPO_ROOT
from stillframe.node_runtime.qos_table import BEGIN, END, rows, table

NODES_MD = REPO_ROOT / "docs" / "nodes.md"


def test_the_page_holds_the_generated_table() -> None:
    page = NODES_MD.read_text()
    assert page.count(BEGIN) == 1 and page.count(END) == 1
    start, end = page.index(BEGIN), page.index(END) + len(END)
    assert page[start:end] == table(), \
        "run: python -m stillframe.node_runtime.qos_table docs/nodes.md"


def test_lockstep_sensors_are_reliable_and_the_realtime_control_path_is_read_best_effort(
) -> None:
    by_topic = {r[0].strip("`"): r for r in rows()}
    imu = by_topic["floor1/imu"]
    assert imu[1] == "sensor_data"
    assert imu[2] == "RELIABLE, TRANSIENT_LOCAL, KEEP_LAST 5"           # lock-step writer
    assert imu[4] == imu[5] == "BEST_EFFORT, VOLATILE, KEEP_LAST 5"     # as the contract
    cmd = by_topic["pendulum/torque_cmd"]
    assert cmd[4] == "RELIABLE, VOLATILE, KEEP_LAST 10"                 # rmw default
    assert cmd[5] == "BEST_EFFORT, VOLATILE, KEEP_LAST 10"
    assert by_topic["/diagnostics"][3] == "-"
