"""The dashboard page's own JavaScript, run by Node.js on a snapshot of :class:`Dashboard` (a
stand-in records what it hands Plotly): the command chart's axes in N·m and N with the limits
drawn on them, the controller's start marked on every chart, the right axes ticked on round
values (tickmode ``auto``: Plotly gives an overlaying axis ``sync`` ticks, the odd values of
issue 28) and every axis title with its unit."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import threading
from importlib import resources

import pytest

from stillframe.identification.tracker import mode_records
from stillframe.monitor.dashboard import CHARTS, SERIES, Dashboard, Limits, Series

NODE = shutil.which("node")
STUB = """
const captured = {}, elements = {};
globalThis.document = {getElementById: id => (elements[id] ??= {textContent: "", innerHTML: ""})};
globalThis.Plotly = {react: (id, traces, layout) => { captured[id] = {traces, layout}; }};
globalThis.fetch = async () => ({json: async () => SNAPSHOT});
globalThis.setTimeout = () => {};
"""


def snapshot(limits: Limits, *, torque: bool = True, force: bool = True) -> dict:
    board = object.__new__(Dashboard)   # the page's data, without a node to follow topics
    board.limits, board._lock, board.diagnostics = limits, threading.Lock(), {}
    board.tracked_modes, board.tracked_updates = [], 0
    board.series = {name: Series(10) for name in SERIES}
    skipped = {name for name, wanted in (("torque_cmd", torque), ("force_cmd", force))
               if not wanted}
    for k in range(5):
        for name in set(SERIES) - skipped:
            width = 4 if name in ("truth", "estimate") else 1
            board.series[name].keep((0.5 * k, [0.1 * k] * width))
    return board.snapshot()


def run_page(data: dict, element: str = "") -> dict:
    html = resources.files("stillframe").joinpath("data/dashboard.html").read_text()
    script = re.search(r"<script>\n(.*?)</script>", html, re.S)[1]
    code = (f"const SNAPSHOT = {json.dumps(data)};\n{STUB}\n{script}\n"
            "setImmediate(() => console.log(JSON.stringify("
            f"{'elements[' + json.dumps(element) + '].innerHTML' if element else 'captured'})));")
    done = subprocess.run([NODE, "-e", code], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


@pytest.mark.skipif(NODE is None, reason="needs Node.js (apt-get install nodejs)")
@pytest.mark.parametrize(("torque", "force"), [(True, True), (False, True), (True, False)])
def test_the_page_draws_units_limits_and_the_controller_start(torque: bool, force: bool) -> None:
    limits = Limits(command=0.5, torque=0.8, force=3.0, controller_start=1.5)
    drawn = run_page(snapshot(limits, torque=torque, force=force))
    assert set(drawn) == set(CHARTS)
    for name, (title, left, right) in CHARTS.items():
        layout = drawn[name]["layout"]
        assert layout["title"]["text"] == title
        assert layout["xaxis"]["title"]["text"] == "t [s]"
        assert layout["yaxis"]["title"]["text"] == left
        if right and (name != "command" or force):
            assert layout["yaxis2"]["title"]["text"] == right
            assert layout["yaxis2"]["tickmode"] == "auto"
        assert [s["x0"] for s in layout["shapes"]] == [1.5]
        assert layout["annotations"][0]["text"] == "controller on"
    command = drawn["command"]
    assert command["layout"]["yaxis"]["title"]["text"] == "torque [N·m]"
    assert ("yaxis2" in command["layout"]) == force   # no empty force axis
    lines = {(t["name"], t.get("yaxis", "y")): sorted({abs(v) for v in t["y"]})
             for t in command["traces"] if t["name"].endswith("limit") and t["y"]}
    # each limit on its command's axis; the controller's on the axis of the command it drives
    expected = {("command limit", "y" if torque else "y2"): [0.5]}
    if torque:
        expected[("torque limit", "y")] = [0.8]
    if force:
        expected[("force limit", "y2")] = [3.0]
    assert lines == expected
    forces = [t for t in command["traces"] if t["name"] == "force"]
    assert [t["yaxis"] for t in forces] == (["y2"] if force else [])


@pytest.mark.skipif(NODE is None, reason="needs Node.js (apt-get install nodejs)")
def test_no_start_marker_without_a_scene() -> None:
    drawn = run_page(snapshot(Limits()))
    assert all(drawn[name]["layout"]["shapes"] == [] for name in CHARTS)


@pytest.mark.skipif(NODE is None, reason="needs Node.js (apt-get install nodejs)")
def test_the_tracked_modes_table_shows_each_mode_with_its_intervals() -> None:
    """Two modes of an ``identification/modes`` message's data: one row each, frequency and
    damping with their 95 % intervals; before the tracker's first update no table at all."""
    data = snapshot(Limits())
    assert run_page(data, "modes") == ""
    data["tracked_modes"] = {"updates": 3, "modes": mode_records(
        [1.6512, 0.0213, 1.6401, 1.6623, 0.0151, 0.0275,
         5.0487, 0.0104, 5.0312, 5.0662, 0.0072, 0.0136])}
    rows = re.findall(r'<tr data-mode="(\d)">(.*?)</tr>', run_page(data, "modes"))
    cells = {n: re.findall(r"<td>(.*?)</td>", row) for n, row in rows}
    assert cells == {"1": ["1.651", "1.640 – 1.662", "0.0213", "0.0151 – 0.0275"],
                     "2": ["5.049", "5.031 – 5.066", "0.0104", "0.0072 – 0.0136"]}
