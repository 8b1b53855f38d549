"""``stillframe ph convergence|fourbar|crank-slider``: the validation cases of seed 000 §6
(and the journal version's manufactured-solution test) on the port-Hamiltonian library."""

from __future__ import annotations

import argparse
import itertools
import sys

import numpy as np

from stillframe.app.arguments import add_json_argument, emit_json, whole
from stillframe.dynamics.ph import crank_slider, fourbar
from stillframe.dynamics.ph.manufactured import l2_errors, observed_rates
from stillframe.errors import InputError
from stillframe.files import check_output, save_figure
from stillframe.text_table import format_table


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe ph``, its arguments and :func:`run` as its action to ``sub``."""
    parser = sub.add_parser("ph", help="port-Hamiltonian multibody validation cases (seed 000)")
    cases = parser.add_subparsers(dest="case", metavar="CASE")
    cases.required = True

    conv = cases.add_parser("convergence", help="manufactured-solution L2 error rates")
    conv.add_argument("--elements", type=whole(1, 1024), nargs="+", default=[8, 16, 32, 64],
                      help="meshes (each twice the previous)")
    add_json_argument(conv)

    bars = cases.add_parser("fourbar", help="four-bar pulsations at a crank angle (§6.1)")
    bars.add_argument("--crank-angle", type=float, required=True, metavar="DEG")
    bars.add_argument("--elements", type=whole(1, 1024), default=4, help="elements per link")
    bars.add_argument("--count", type=whole(1, 1000), default=3, help="pulsations to print")
    bars.add_argument("--plot", metavar="PNG", help="sweep the crank angle and plot (Fig. 6)")
    add_json_argument(bars)

    crank = cases.add_parser("crank-slider", help="rotating crank-slider, coupler midpoint (§6.2)")
    crank.add_argument("--elements", type=whole(2, 1024), default=4, help="coupler elements (even)")
    crank.add_argument("--dt", type=float, default=2e-5, help="time step [s]")
    crank.add_argument("--crank-angle-end", type=float, default=8.0, metavar="RAD")
    crank.add_argument("--plot", metavar="PNG", help="midpoint deformation over the crank angle")
    add_json_argument(crank)
    parser.set_defaults(func=run)


def _progress(text: str) -> None:
    print(f"ph: {text}", file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    """Run the chosen validation case and print its table (``--plot`` as asked); exit code 0."""
    check_output("--plot", getattr(args, "plot", None))
    return {"convergence": _convergence, "fourbar": _fourbar,
            "crank-slider": _crank_slider}[args.case](args)


def _convergence(args: argparse.Namespace) -> int:
    meshes = args.elements
    if len(meshes) < 2 or any(b != 2 * a for a, b in itertools.pairwise(meshes)):
        raise InputError("ph convergence: --elements needs >= 2 meshes, each twice the previous")
    errors = []
    for n in meshes:
        _progress(f"convergence: {n} elements")
        errors.append(l2_errors(n))
    rates = observed_rates(errors)
    doc = {"elements": meshes, "dt": [e.dt for e in errors],
           "errors": {k: [getattr(e, k) for e in errors]
                      for k in ("displacement", "velocity", "moment")},
           "rates": rates}
    if args.json:
        emit_json(doc)
        return 0
    rows = [[n, e.dt, e.displacement, e.velocity, e.moment,
             *(rates[k][i - 1] if i else "" for k in ("displacement", "velocity", "moment"))]
            for i, (n, e) in enumerate(zip(meshes, errors, strict=True))]
    print(format_table(["elements", "dt [s]", "|u err|", "|v err|", "|m err|", "rate u",
                        "rate v", "rate m"], rows))
    return 0


def _fourbar(args: argparse.Namespace) -> int:
    if args.elements < 1 or args.count < 1:
        raise InputError("ph fourbar: --elements and --count must be >= 1")
    angle = np.radians(args.crank_angle)
    ph = fourbar.ph_pulsations(angle, args.elements, args.count)
    ref = fourbar.classical_pulsations(angle, args.elements, args.count)
    if args.plot:
        _fourbar_plot(args.plot, args.elements)
    if args.json:
        emit_json({"crank_angle_deg": args.crank_angle, "elements": args.elements,
                   "pulsations_rad_s": ph.tolist(), "classical_fe_rad_s": ref.tolist(),
                   "max_relative_difference": float(np.max(np.abs(ph - ref) / ref))})
        return 0
    rows = [[i + 1, p, r, abs(p - r) / r] for i, (p, r) in enumerate(zip(ph, ref, strict=True))]
    print(format_table(["mode", "pH [rad/s]", "classical FE [rad/s]", "rel. diff"], rows))
    return 0


def _fourbar_plot(path: str, elements: int) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    angles = np.arange(0.0, 361.0, 10.0)
    values = []
    for a in angles:
        _progress(f"fourbar sweep: {a:.0f} deg")
        values.append(fourbar.ph_pulsations(np.radians(a), elements, 3))
    fig, ax = plt.subplots(figsize=(6, 4))
    ax.plot(angles, np.asarray(values), marker=".")
    ax.set_xlabel("crank angle θ₁ [deg]")
    ax.set_ylabel("pulsation ω [rad/s]")
    ax.set_title(f"four-bar, first three pulsations ({elements} el./link)")
    ax.legend(["ω₁", "ω₂", "ω₃"])
    ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)


def _crank_slider(args: argparse.Namespace) -> int:
    if args.dt <= 0 or args.crank_angle_end <= 0:
        raise InputError("ph crank-slider: --dt and --crank-angle-end must be > 0")
    t_end = args.crank_angle_end / crank_slider.CrankSliderData().crank_rate
    run_ = crank_slider.simulate(args.elements, t_end, args.dt,
                                 progress=lambda t: _progress(f"crank-slider t = {t:.4f} s")
                                 if round(t / args.dt) % 500 == 0 else None)
    if args.plot:
        _crank_plot(args.plot, run_)
    doc = {"crank_angle_rad": run_.crank_angle.tolist(),
           "w_mid_over_L": run_.w_mid_over_l.tolist(),
           "u_mid_over_L": run_.u_mid_over_l.tolist(),
           "energy_balance_error": run_.energy_balance_error,
           "max_constraint_drift": run_.max_constraint_drift}
    if args.json:
        emit_json(doc)
        return 0
    print(format_table(
        ["elements", "dt [s]", "max |w_mid|/L", "max |u_mid|/L", "energy balance err",
         "constraint drift [m]"],
        [[args.elements, args.dt, float(np.max(np.abs(run_.w_mid_over_l))),
          float(np.max(np.abs(run_.u_mid_over_l))), run_.energy_balance_error,
          run_.max_constraint_drift]]))
    return 0


def _crank_plot(path: str, run_: crank_slider.CrankSliderRun) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(9, 3.5))
    axes[0].plot(run_.crank_angle, run_.u_mid_over_l)
    axes[0].set_ylabel("u_f^x(L/2) / L [-]")
    axes[1].plot(run_.crank_angle, run_.w_mid_over_l)
    axes[1].set_ylabel("u_f^y(L/2) / L [-]")
    for ax in axes:
        ax.set_xlabel("crank angle [rad]")
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    save_figure(fig, path, dpi=120)
