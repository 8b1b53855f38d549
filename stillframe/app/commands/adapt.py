"""``stillframe adapt SCENE``: the fixed controller, the adaptive loop and the oracle on one
change scene through the nodes (lock-step, the same seeds), and what the adaptation did.

Prints when the structure changed and when the loop noticed it, the frequencies it identified
against the true changed model's, each run's peak reductions after the change per floor and
the adaptive loop's share of the oracle's, with the adaptation's targets (detection within 15 s,
frequencies within 1 %, at least 90 % of the oracle's displacement reductions on every floor)
met or missed; ``--json`` prints ``{"adaptation": {"change_at_s", "detected_at_s",
"identified_hz", "true_hz", "reduction_pct": {"fixed", "adaptive", "oracle"}}, "details":
{...}}`` (:mod:`stillframe.app.adaptation_experiment`). Each run's files go under ``--out``,
with the timeline figure ``timeline.png`` (frequencies, detection, hand-over, floor responses).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from stillframe.app.arguments import add_scene_arguments, emit_json
from stillframe.files import check_output, write_text
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe adapt``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("adapt", help="fixed, adaptive and oracle LQG across a change of "
                                          "the structure, through the nodes",
                            description=__doc__.split("\n\n", 1)[1])
    add_scene_arguments(parser)
    parser.add_argument("--out", type=Path, default=Path("out/adapt"), metavar="DIR",
                        help="output directory (default out/adapt; an earlier run's files are "
                             "replaced)")
    parser.set_defaults(func=run)


def _progress(text: str) -> None:
    print(f"stillframe adapt: {text}", file=sys.stderr, flush=True)


def print_report(doc: dict) -> None:
    """Print the adaptation document ``doc`` as tables: the change and its detection, the identified
    against the design model's and the true frequencies, each run's reductions per floor and the
    adaptive loop's share of the oracle's, each target met or missed, and every refused design."""
    a, d = doc["adaptation"], doc["details"]
    t = d["targets"]

    def met(ok: bool) -> str:
        return "met" if ok else "MISSED"

    detected = ("not detected" if a["detected_at_s"] is None else
                f"detected at {a['detected_at_s']:.5g} s (delay {d['detection_delay_s']:.3g} s, "
                f"target {t['detection_within_s']:g} s: {met(t['detection_met'])})")
    print(f"scene {doc['scene']}: change at {a['change_at_s']:.5g} s, {detected}")
    if d["handover_s"] is not None:
        w = d["identification_window_s"]
        print(f"identified from {w[0]:.5g}-{w[1]:.5g} s, design handed over at "
              f"{d['handover_s']:.5g} s")
    if a["identified_hz"] is not None:
        rows = [[f"mode {i + 1}", f"{f:.4f}", f"{g:.4f}", f"{h:.4f}", f"{100 * e:.2f}"]
                for i, (f, g, h, e) in enumerate(zip(
                    a["identified_hz"], d["design_hz"], a["true_hz"], d["frequency_error"],
                    strict=True))]
        print(format_table(["", "identified Hz", "design model Hz", "true Hz", "error %"],
                           rows))
        print(f"frequencies within {100 * t['frequency_error_within']:g} %: "
              f"{met(t['frequency_met'])}")
    r = a["reduction_pct"]
    rows = [[f"floor {i + 1}", *(f"{r[n]['displacement'][i]:.2f}" for n in
                                 ("fixed", "adaptive", "oracle")),
             f"{100 * d['adaptive_over_oracle_displacement'][i]:.1f}",
             *(f"{r[n]['velocity'][i]:.2f}" for n in ("fixed", "adaptive", "oracle"))]
            for i in range(3)]
    print(format_table(["", "disp. fixed %", "adaptive %", "oracle %", "adaptive/oracle %",
                        "vel. fixed %", "adaptive %", "oracle %"], rows))
    print(f"adaptive at least {100 * t['oracle_share_at_least']:g} % of the oracle on every "
          f"floor: {met(t['oracle_share_met'])}")
    for refusal in d["refusals"]:
        print(f"refused design at {refusal['t']:.5g} s: {refusal['reason']}")


def run(args: argparse.Namespace) -> int:
    """Run the fixed, adaptive and oracle launches, write ``adapt.json`` and ``timeline.png`` under
    ``--out`` and print the report (``--json``: the document); exit code 0, a dead node's code
    (:func:`~stillframe.app.launch_cli.report_death`), or 130 when interrupted."""
    from stillframe.app.adaptation_experiment import run_adaptation_experiment
    from stillframe.app.adaptation_plot import plot_timeline
    from stillframe.app.launch_cli import report_death
    from stillframe.app.launcher import NodeDiedError

    check_output("--out", args.out, folder=True)
    try:
        doc, results = run_adaptation_experiment(Path(args.scene), args.overrides, out=args.out,
                                                 progress=_progress)
    except NodeDiedError as exc:
        return report_death("adapt", exc)
    except KeyboardInterrupt:
        print("stillframe adapt: interrupted; every node stopped", file=sys.stderr)
        return 130
    figure = args.out / "timeline.png"
    plot_timeline(figure, doc, results)
    doc["details"]["figure"] = str(figure)
    write_text(args.out / "adapt.json", json.dumps(doc, indent=2) + "\n", what="result file")
    if args.json:
        emit_json(doc)
    else:
        print_report(doc)
        print(f"figure {figure}, runs under {args.out}")
    return 0
