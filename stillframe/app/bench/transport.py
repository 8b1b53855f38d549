"""``stillframe bench transport``: ping-pong RTT between two processes: raw Cyclone, and the node
API on each backend (Cyclone through ``dds``, Fast DDS through real rclpy), interleaved in one run.

See :mod:`stillframe.app.bench.pingpong` for what is measured and how.
"""

from __future__ import annotations

import argparse

from stillframe.app.arguments import add_json_argument, emit_json, seconds
from stillframe.errors import InputError
from stillframe.text_table import format_table


def register(benches: argparse._SubParsersAction) -> None:
    """Add ``stillframe bench transport``, its arguments and :func:`run` as its action to
    ``benches``."""
    parser = benches.add_parser(
        "transport", help="ping-pong RTT between two processes: raw Cyclone DDS and the node API "
                          "on each backend"
    )
    parser.add_argument("--duration", type=seconds, default=10.0, metavar="S",
                        help="seconds of pinging per variant (default 10)")
    parser.add_argument("--rate", type=float, default=1000.0, metavar="HZ",
                        help="pings per second (default 1000; 0: back to back, the next ping "
                             "as soon as the pong is in, as a lock-step loop goes)")
    add_json_argument(parser)
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Run the benchmark the module's docstring describes and print its figures (``--json``: one
    document); exit code 0."""
    if not args.duration > 0 or not args.rate >= 0:
        raise InputError("bench transport: --duration must be > 0 and --rate >= 0")
    from stillframe.app.bench.pingpong import IMU, measure
    from stillframe.middleware import api

    results = measure(args.rate, args.duration)
    backends = [b for b in api.BACKENDS if b in results]
    keys = ("p50_us", "p99_us")
    ratios = {v: {k: results[v][k] / results["raw"][k] for k in keys}
              for v in (*backends, "dds_raw")}
    document = {"message": IMU, "qos": "sensor_data", "rate_hz": args.rate,
                "duration_s": args.duration, "backends": backends,
                **results, "api_over_raw": ratios}
    if "rclpy" in results:
        document["rclpy_over_dds"] = {k: results["rclpy"][k] / results["dds"][k] for k in keys}
    if args.json:
        emit_json(document)
        return 0
    rows = [[name, r["sent"], r["lost"], r["p50_us"], r["p99_us"], r["max_us"]]
            for name, r in results.items()]
    print(format_table(["variant", "sent", "lost", "p50 [us]", "p99 [us]", "max [us]"], rows))
    for variant, ratio in ratios.items():
        print(f"API on {variant} / raw Cyclone: p50 x{ratio['p50_us']:.2f}, "
              f"p99 x{ratio['p99_us']:.2f}")
    if "rclpy_over_dds" in document:
        r = document["rclpy_over_dds"]
        print(f"rclpy / dds: p50 x{r['p50_us']:.2f}, p99 x{r['p99_us']:.2f}")
    return 0
