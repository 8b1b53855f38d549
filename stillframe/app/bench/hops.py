"""``stillframe bench hops``: what each hop of one real-time sample costs (the profile of
docs/realtime.md): the plant, serialization and reading of each message (the fixed-layout codecs
beside ``rosbags``, ratio in the same run), the filter, the control law, and the DDS write and
take on each backend. The wake-up of another process is ``bench transport``'s round trip.
"""

from __future__ import annotations

import argparse

from stillframe.app.arguments import add_json_argument, emit_json
from stillframe.errors import InputError
from stillframe.locations import SCENES_DIR
from stillframe.text_table import format_table

SCENE = SCENES_DIR / "thesis_lqg.yaml"


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench hops``, its arguments and :func:`run` as its action to ``benches``."""
    parser = benches.add_parser("hops", help="cost of each hop of one real-time sample",
                                description=__doc__.split("\n", 1)[1])
    parser.add_argument("--number", type=int, default=200, metavar="N",
                        help="calls per timed round (default 200; 7 rounds, median)")
    parser.add_argument("--backend", dest="backends", action="append", default=[],
                        help="time the DDS hops on this backend (repeatable; default: every one "
                             "installed)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    if args.number < 1:
        raise InputError("bench hops: --number must be >= 1")
    from stillframe.app.bench.hop_profile import compute_hops, dds_hops
    from stillframe.config.scene import load_scene
    from stillframe.middleware import api

    scene = load_scene(SCENE, ["sensors.rate_hz=1000", "integrator.dt=0.001",
                               "controller.start=1", "evaluation.window=1"])
    backends = args.backends or [b for b in api.BACKENDS if b == "dds" or api.has_rclpy()]
    for backend in backends:
        api.check_backend(backend, f"bench hops --backend {backend}")
    rows = [*compute_hops(scene, args.number), phase_timing_hop(args.number)]
    for backend in backends:
        rows += dds_hops(scene, backend, args.number)
    if args.json:
        emit_json({"scene": scene.name, "rate_hz": scene.sensors.rate_hz, "hops": rows})
        return 0
    print(format_table(
        ["node", "hop", "us", "rosbags [us]", "rosbags / fixed"],
        [[r["node"], r["hop"], f"{r['us']:.1f}",
          "" if r["rosbags_us"] is None else f"{r['rosbags_us']:.1f}",
          "" if r["rosbags_us"] is None else f"{r['rosbags_us'] / r['us']:.1f}"]
         for r in rows]))
    return 0


def phase_timing_hop(number: int, repeats: int = 7) -> dict[str, object]:
    """What sim_node's phase timing (:mod:`stillframe.node_runtime.phase_timing`) costs a
    sample: a row begun, every mark made, the counters read."""
    from stillframe.app.bench.hop_profile import per_call_us
    from stillframe.node_runtime.phase_timing import MARKS, PhaseLog

    timing = PhaseLog("sim_node", MARKS["sim_node"], capacity=number)
    slots = list(timing.slots.values())

    def row() -> None:
        timing.begin(1_000_000)
        for slot in slots[:-1]:
            timing.mark(slot)
        timing.end(slots[-1])

    return {"node": "sim_node", "hop": f"phase timing of a sample ({len(slots)} marks, counters)",
            "us": per_call_us(row, number, repeats), "rosbags_us": None}
