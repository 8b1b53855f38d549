"""``stillframe experiment SCENE``: identify the structure through the nodes, design the LQG on
it, control the plant, and compare with the design on the true model (thesis §5.5–5.6; the steps
are in :mod:`stillframe.app.experiment`).

Prints identified against true M, K, R with relative errors and the reductions of both designs
per floor with their ratio; ``--json`` prints the same as one document; writes the bag, the model
file, each run's results, ``experiment.json`` and ``comparison.png`` into ``--out``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from stillframe import interrupts
from stillframe.app.arguments import add_scene_arguments, emit_json
from stillframe.app.launch_cli import add_launch_arguments, report_death
from stillframe.files import check_output


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe experiment``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser(
        "experiment", help="identify through the nodes, design LQG on it, compare with the "
                           "design on the true model", description=__doc__.split("\n\n", 1)[1])
    add_scene_arguments(parser)
    add_launch_arguments(parser)
    parser.add_argument("--out", type=Path, default=Path("out/experiment"), metavar="DIR",
                        help="output directory (default out/experiment; an earlier run's files "
                             "are replaced)")
    parser.add_argument("--test-force", type=float, default=None, metavar="N",
                        help="std of the test's white-noise force on floor 1 (default 0.1 N, or "
                        "10 dB above the response to the plant's process noise)")
    parser.add_argument("--test-duration", type=float, default=64.0, metavar="S",
                        help="length of the identification test (default 64 s)")
    parser.add_argument("--test-seed", type=int, default=0, metavar="SEED",
                        help="seed of the test's force")
    parser.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Identify, design and control as :mod:`stillframe.app.experiment` does and print the
    comparison; exit code 0, a dead node's code, or 130/143 when interrupted."""
    from stillframe.app.experiment import IdentificationTest, run_experiment, write_summary
    from stillframe.app.experiment_report import document, plot_comparison, print_report
    from stillframe.app.launcher import NodeDiedError

    check_output("--out", args.out, folder=True)

    test = IdentificationTest(args.test_force, args.test_duration, args.test_seed)
    try:
        result = run_experiment(Path(args.scene), args.overrides, args.out, test,
                                mode=args.mode, lockstep_timeout_s=args.lockstep_timeout,
                                backends=args.backends)
    except NodeDiedError as exc:
        return report_death("experiment", exc)
    except KeyboardInterrupt as exc:
        print("stillframe experiment: interrupted; every node stopped", file=sys.stderr)
        return interrupts.exit_code(exc)
    doc = document(result)
    plot_comparison(args.out / "comparison.png", result, doc)
    doc["files"]["plot"] = str(args.out / "comparison.png")
    write_summary(args.out, doc)
    for warning in doc["identification"]["warnings"]:
        print(f"stillframe experiment: warning: {warning}", file=sys.stderr)
    if args.json:
        emit_json(doc)
    else:
        print_report(doc)
        print(f"bag {doc['files']['bag']}, model {doc['files']['model']}, plot "
              f"{doc['files']['plot']}")
    return 0
