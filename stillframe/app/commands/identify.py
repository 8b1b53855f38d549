"""``stillframe identify BAG``: a state-space model and its modes from a rosbag2 recording.

Inputs and outputs are ``TOPIC[:FIELD]`` channels (see :mod:`stillframe.bags.channels`);
the model comes from :func:`stillframe.identification.pipeline.identify` (OKID + ERA or ERA/DC,
thesis ch. 3).
"""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING, Any

from stillframe.app.arguments import Progress, add_json_argument, emit_json
from stillframe.errors import InputError
from stillframe.files import check_output

if TYPE_CHECKING:
    from stillframe.bags.channels import Record
    from stillframe.identification.mkr import PhysicalModel
    from stillframe.identification.pipeline import Identification
    from stillframe.identification.ssi_cov import OutputOnlyIdentification


def _order(text: str) -> int | str:
    if text == "auto":
        return text
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is neither a positive integer nor auto"
                                         ) from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"{value} is not a positive integer")
    return value


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``stillframe identify``, its arguments and :func:`run` as its action to ``sub``."""
    from stillframe.identification.pipeline import METHODS, NOISE_MODELS
    from stillframe.identification.ssi_cov import OUTPUT_ONLY_METHODS

    parser = sub.add_parser(
        "identify", help="identify a state-space model and its modes from a rosbag2 bag",
        description="Identify a discrete state-space model (OKID + ERA or ERA/DC) and its modes "
                    "from input and output channels recorded in a rosbag2 bag.")
    parser.add_argument("bag", metavar="BAG", help="rosbag2 bag directory (or a lone .mcap file)")
    parser.add_argument("--input", dest="inputs", action="append", default=[],
                        metavar="TOPIC[:FIELD]", help="input channel (repeatable), e.g. "
                        "/frame/excitation/wrench:wrench.force.x")
    parser.add_argument("--output", dest="outputs", action="append", default=[],
                        metavar="TOPIC[:FIELD]", help="output channel (repeatable), e.g. "
                        "/frame/floor1/imu:linear_acceleration.x")
    parser.add_argument("--method", choices=(*METHODS, *OUTPUT_ONLY_METHODS),
                        default="okid-eradc",
                        help="input-output methods (default okid-eradc), or ssi-cov: output-only "
                        "(operational modal analysis, no --input)")
    parser.add_argument("--order", type=_order, default="auto", metavar="N|auto",
                        help="model order, or auto: the largest Hankel singular-value gap")
    parser.add_argument("--max-order", type=int, default=None, metavar="N",
                        help="largest order that --order auto may choose")
    parser.add_argument("--observer-order", type=int, default=None, metavar="P",
                        help="OKID observer order p (default 20, lowered for short records)")
    parser.add_argument("--combined", action="store_true",
                        help="OKID methods: realize [Y_k, Y0_k] together, giving B and the "
                        "observer gain at once (thesis eqs. 3.165-3.203)")
    parser.add_argument("--fast", action="store_true",
                        help="skip the prediction-error refinement (the default refines the OKID "
                        "model and gives each mode a 95 %% interval); every other check still "
                        "runs and the result warns that it is not refined")
    parser.add_argument("--refine", action="store_true",
                        help="the default for the OKID methods; kept for older scripts")
    parser.add_argument("--noise-model", choices=NOISE_MODELS, default=NOISE_MODELS[0],
                        help="the refined model's structure: innovations (default: the Kalman "
                        "gain estimated with the model, K = 0 kept where BIC prefers it; the one "
                        "for closed-loop records) or output-error (K = 0: the simulation error "
                        "from the input alone)")
    parser.add_argument("--detrend", action="store_true", help="remove a linear trend first")
    parser.add_argument("--lowpass", type=float, default=None, metavar="HZ",
                        help="zero-phase Butterworth low-pass on inputs and outputs")
    parser.add_argument("--decimate", type=int, default=1, metavar="Q",
                        help="keep every Q-th sample after a zero-phase anti-alias filter")
    parser.add_argument("--max-jitter", type=float, default=None, metavar="FRACTION",
                        help="largest sampling-step deviation accepted (default 0.05 of a step)")
    add_json_argument(parser)
    parser.add_argument("--plots", metavar="DIR", default=None, help="write PNG figures here")
    parser.add_argument("--save-model", metavar="FILE", default=None,
                        help="write the identified model file")
    parser.add_argument("--mkr", metavar="SENSOR_DOFS:ACTUATOR_DOFS", default=None,
                        help="also identify M, K, R (thesis §3.7): the DOF of each output and of "
                        "each input, e.g. 0,1,2:0 for three floor sensors and a force on floor 1")
    parser.add_argument("--output-type", choices=("acceleration", "velocity", "displacement"),
                        default="acceleration", help="what the outputs measure (for --mkr)")
    parser.add_argument("--progress", action="store_true",
                        help="show progress on stderr (default: when stderr is a terminal)")
    parser.set_defaults(func=run)


def _dofs(text: str, what: str) -> list[int]:
    try:
        return [int(d) for d in text.split(",")]
    except ValueError:
        raise InputError(f"--mkr: {what} DOFs {text!r} must be comma-separated integers"
                         ) from None


def _physical(args: argparse.Namespace, ident: Identification
              ) -> tuple[PhysicalModel | None, dict[str, Any]]:
    """MKR matrices and the least-squares Rayleigh α, β of the identified modes (eq. 3.213)."""
    if args.mkr is None:
        return None, {}
    from stillframe.identification.damping import fit_proportional_damping
    from stillframe.identification.mkr import mkr

    sensors, sep, actuators = args.mkr.partition(":")
    if not sep:
        raise InputError(f"--mkr {args.mkr!r}: expected SENSOR_DOFS:ACTUATOR_DOFS, e.g. 0,1,2:0")
    physical = mkr(ident.A, ident.B, ident.C, ident.dt, _dofs(sensors, "sensor"),
                   _dofs(actuators, "actuator"), args.output_type)
    alpha, beta = fit_proportional_damping(ident.modes.omega, ident.modes.damping_ratio)
    return physical, {"M": physical.M.tolist(), "K": physical.K.tolist(),
                      "R": physical.R.tolist(), "rayleigh_alpha": alpha, "rayleigh_beta": beta}


def _report_progress(ident: Identification | OutputOnlyIdentification, args: argparse.Namespace,
                     record: Record, progress: Progress) -> None:
    """Order and modes on the progress line, each warning on stderr, the figures with --plots."""
    from stillframe.identification.plots import identification_plots, output_only_plots
    from stillframe.identification.ssi_cov import OutputOnlyIdentification

    progress(f"order {ident.order}, {len(ident.modes)} modes")
    for warning in ident.warnings:
        print(f"stillframe identify: warning: {warning}", file=sys.stderr)
    if args.plots:
        progress(f"writing plots to {args.plots}")
        if isinstance(ident, OutputOnlyIdentification):
            output_only_plots(ident, record, args.plots)
        else:
            identification_plots(ident, record, args.plots)


def run_output_only(args: argparse.Namespace, record: Record, progress: Progress) -> int:
    """``--method ssi-cov``: SSI-COV on the outputs (:mod:`stillframe.identification.ssi_cov`)."""
    from stillframe.identification.report import modes_table, output_only_document
    from stillframe.identification.ssi_cov import identify_output_only

    for option, given in (("--mkr", args.mkr), ("--save-model", args.save_model),
                          ("--fast", args.fast), ("--combined", args.combined)):
        if given:
            raise InputError(f"{option} needs an input-output model: not with --method ssi-cov")
    ident = identify_output_only(record.y, record.dt, args.order, max_order=args.max_order,
                                 output_names=[str(c) for c in record.outputs])
    _report_progress(ident, args, record, progress)
    if args.json:
        emit_json(output_only_document(ident, args.order == "auto"))
        return 0
    names = [str(c) for c in record.outputs]
    print(f"{args.bag}: {record.samples} samples, dt = {record.dt:g} s; method ssi-cov "
          f"(output-only, {ident.block_rows} block rows), order {ident.order}")
    print("outputs: " + ", ".join(f"y{i + 1} = {n}" for i, n in enumerate(names)))
    print(modes_table(ident.modes, ident.consistent, [f"y{i + 1}" for i in range(len(names))],
                      ident))
    return 0


def run(args: argparse.Namespace) -> int:
    """Read the channels from the bag, identify the model and print its modes (``--save-model``,
    ``--plots`` and ``--json`` as asked); exit code 0. Output-only methods (``ssi-cov``) take their
    own path."""
    from stillframe.bags.channels import DEFAULT_JITTER, Channel, read_record
    from stillframe.identification.pipeline import identify
    from stillframe.identification.report import (
        format_matrix,
        identification_document,
        modes_table,
        refinement_text,
    )

    check_output("--save-model", args.save_model)
    check_output("--plots", args.plots, folder=True)

    progress = Progress(args.progress or sys.stderr.isatty())
    inputs = [Channel.parse(s) for s in args.inputs]
    outputs = [Channel.parse(s) for s in args.outputs]
    jitter = DEFAULT_JITTER if args.max_jitter is None else args.max_jitter
    if not 0 < jitter < 0.5:
        raise InputError(f"--max-jitter {jitter}: must lie between 0 and 0.5")
    progress(f"reading {args.bag}")
    output_only = args.method == "ssi-cov"
    record = read_record(args.bag, inputs, outputs, detrend=args.detrend,
                         lowpass_hz=args.lowpass, decimate=args.decimate, max_jitter=jitter,
                         output_only=output_only)
    if output_only:
        return run_output_only(args, record, progress)
    progress(f"{record.samples} samples at {1 / record.dt:g} Hz; identifying ({args.method})")
    if args.fast and args.refine:
        raise InputError("--fast skips the refinement that --refine asks for: give one")
    ident = identify(record.u, record.y, record.dt, args.method, args.order,
                     observer_order=args.observer_order, max_order=args.max_order,
                     combined=args.combined, refine=False if args.fast else None,
                     noise_model=args.noise_model, input_names=[str(c) for c in record.inputs],
                     output_names=[str(c) for c in record.outputs])
    _report_progress(ident, args, record, progress)
    physical, physical_doc = _physical(args, ident)
    if physical is not None:
        from stillframe.identification.structure_model import unresolved_pulse

        if (pulse := unresolved_pulse(record.u)) is not None:
            physical_doc["scale_warning"] = pulse
            print(f"stillframe identify: warning: {pulse}", file=sys.stderr)
    if args.save_model:
        from stillframe.identification.model_file import model_from_identification, save_model

        provenance = {"bag": str(args.bag), "inputs": [str(c) for c in record.inputs],
                      "outputs": [str(c) for c in record.outputs], **record.preprocessing}
        if physical is not None:
            provenance |= {"mkr": {"dofs": args.mkr, "output": args.output_type},
                           "rayleigh_alpha": physical_doc["rayleigh_alpha"],
                           "rayleigh_beta": physical_doc["rayleigh_beta"]}
        save_model(args.save_model, model_from_identification(
            ident, provenance["inputs"], provenance["outputs"], provenance, physical))
        progress(f"model written to {args.save_model}")
    doc = identification_document(ident, args.order == "auto") | physical_doc
    if args.json:
        emit_json(doc)
        return 0
    names = [str(c) for c in record.outputs]
    print(f"{args.bag}: {record.samples} samples, dt = {record.dt:g} s; method {ident.method}, "
          f"order {ident.order}"
          + (f" (auto: gap sigma_n/sigma_n+1 = {ident.order_gap:.4g})" if args.order == "auto"
             else ""))
    print("outputs: " + ", ".join(f"y{i + 1} = {n}" for i, n in enumerate(names)))
    if ident.refinement is not None:
        print(refinement_text(ident.refinement))
    print(modes_table(ident.modes, ident.consistent, [f"y{i + 1}" for i in range(len(names))],
                      ident.refinement))
    if physical is not None:
        for key in ("M", "K", "R"):
            print(f"{key} =\n{format_matrix(physical_doc[key])}")
        print(f"Rayleigh fit of the modes: alpha = {physical_doc['rayleigh_alpha']:.6g} 1/s, "
              f"beta = {physical_doc['rayleigh_beta']:.6g} s")
    return 0
