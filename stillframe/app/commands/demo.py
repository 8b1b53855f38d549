"""``stillframe demo``: the LQG scene through the three nodes, recorded, tabled and plotted.

Runs ``scenes/thesis_lqg.yaml`` (thesis §5.6) in lock-step through sim_node, estimator_node and
controller_node over DDS while ``stillframe record`` writes every topic into a bag, prints the
reduction table beside the thesis's values (eq. 5.233) and writes a PNG of the three floors'
displacements with control (from sim_node's history) and without (the same scene and seeds with
no command, :func:`stillframe.loop.closed_loop.open_loop_truth`).

The demo is self-contained, so it runs isolated: on a ROS domain of its own (a random
``ROS_DOMAIN_ID`` other than the shell's, or ``--domain-id N``) with discovery on this machine
only (``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``), and says so in one line. Another loop or tool
on the shell's domain or the lab network neither sees it nor is seen; ``ROS_DOMAIN_ID=N
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST stillframe topic list`` watches it.
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import sys
from pathlib import Path

import numpy as np

from stillframe import interrupts
from stillframe.app.arguments import whole
from stillframe.app.launch_cli import add_launch_arguments, print_evaluation, report_death
from stillframe.config import environment
from stillframe.config.environment import MAX_DOMAIN_ID
from stillframe.config.scene import Scene
from stillframe.errors import InputError
from stillframe.files import check_output, save_figure
from stillframe.locations import SCENES_DIR

DEMO_SCENE = SCENES_DIR / "thesis_lqg.yaml"
#: the ROS domain ids a demo may be isolated on, the first to the last
DOMAIN_IDS = (1, MAX_DOMAIN_ID)
#: what a demo run writes into its output directory (replaced on every run)
OUTPUTS = ("bag", "result.json", "result.npz", "floors.png")


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe demo``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("demo", help="LQG through the three nodes: bag, table and plot",
                            description=__doc__.split("\n\n", 1)[1])
    parser.add_argument("--out", type=Path, default=Path("out/demo"), metavar="DIR",
                        help="output directory (default out/demo): bag/, result.json, "
                             "result.npz, floors.png")
    parser.add_argument("--set", dest="overrides", action="append", default=[],
                        metavar="KEY=VALUE", help="override a scene value (repeatable)")
    parser.add_argument("--domain-id", type=whole(*DOMAIN_IDS), default=None, metavar="N",
                        help="the ROS domain the demo runs isolated on (default: a random one "
                             "other than ROS_DOMAIN_ID's)")
    add_launch_arguments(parser)
    parser.set_defaults(func=run)


def isolate(domain_id: int | None) -> str:
    """Put this process and the children it starts on ROS domain ``domain_id`` (None: a random
    one other than the environment's) with discovery on this machine only; the line that says so."""
    if domain_id is None:
        current = environment.value("ROS_DOMAIN_ID")
        domain_id = random.SystemRandom().choice(
            [d for d in range(DOMAIN_IDS[0], DOMAIN_IDS[1] + 1) if str(d) != current])
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return (f"demo: isolated on ROS_DOMAIN_ID={domain_id}, discovery on this machine only "
            "(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST): other loops and tools do not see it; "
            f"ROS_DOMAIN_ID={domain_id} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST stillframe topic "
            "list does")


def clear_previous(out: Path) -> None:
    """Remove what an earlier demo wrote into ``out``; refuse to touch anything else."""
    bag = out / "bag"
    if bag.exists() and not (bag / "metadata.yaml").is_file():
        raise InputError(f"--out {out}: {bag} exists and is not a bag; choose another --out")
    shutil.rmtree(bag, ignore_errors=True)
    for name in OUTPUTS[1:]:
        (out / name).unlink(missing_ok=True)


def plot_floors(path: Path, controlled: tuple[np.ndarray, np.ndarray],
                uncontrolled: tuple[np.ndarray, np.ndarray], scene: Scene) -> None:
    """One panel per floor: displacement over time without and with control (mm)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, sharex=True, figsize=(9, 7), constrained_layout=True)
    for i, ax in enumerate(axes):
        ax.plot(uncontrolled[0], 1e3 * uncontrolled[1][:, i], color="0.6", lw=0.6,
                label="without control")
        ax.plot(controlled[0], 1e3 * controlled[1][:, i], color="C0", lw=0.6,
                label="with control")
        ax.axvline(scene.controller.start, color="C3", ls="--", lw=0.8)
        ax.set_ylabel(f"x{i + 1} [mm]")
    axes[0].legend(loc="upper left", ncol=2, fontsize="small")
    axes[0].set_title(f"{scene.name}: floor displacements, {scene.controller.type} from "
                      f"{scene.controller.start:g} s (dashed)")
    axes[-1].set_xlabel("t [s]")
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def controlled_floors(history_file: Path) -> tuple[np.ndarray, np.ndarray]:
    """sim_node's true floor displacements at every integrator step (its ``.npz``)."""
    with np.load(history_file) as data:
        return data["fine_t"], data["fine_floors"]


def run(args: argparse.Namespace) -> int:
    """Run the demo scene through the three nodes with the recorder, print the table and write the
    bag and ``floors.png`` under ``--out``; exit code 0, a dead node's code
    (:func:`~stillframe.app.commands.launch.report_death`), or 130/143 when interrupted."""
    from stillframe.app.launcher import NodeDiedError, run_scene
    from stillframe.config.scene import load_scene
    from stillframe.loop.closed_loop import open_loop_truth

    check_output("--out", args.out, folder=True)

    scene = load_scene(DEMO_SCENE, args.overrides)
    out: Path = args.out
    clear_previous(out)
    print(isolate(args.domain_id), file=sys.stderr)
    print(f"demo: {scene.name} through sim_node, estimator_node and controller_node "
          f"({args.mode}), recording to {out / 'bag'}", file=sys.stderr)
    try:
        result = run_scene(DEMO_SCENE, args.overrides, out=out, mode=args.mode,
                           record_dir=out / "bag", lockstep_timeout_s=args.lockstep_timeout,
                           backends=args.backends)
    except NodeDiedError as exc:
        return report_death("demo", exc)
    except KeyboardInterrupt as exc:
        print("stillframe demo: interrupted; every node stopped", file=sys.stderr)
        return interrupts.exit_code(exc)
    print_evaluation(result.evaluation, scene)
    t, floors, _ = open_loop_truth(scene)
    plot_floors(out / "floors.png", controlled_floors(result.history_file), (t, floors), scene)
    print(f"bag: {out / 'bag'}   plot: {out / 'floors.png'}   results: {result.result_file}")
    return 0
