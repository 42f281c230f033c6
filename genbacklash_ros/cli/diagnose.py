"""``genbacklash diagnose``: find where model and measurement disagree, name and add the effect.

Registered by :mod:`genbacklash_ros.cli.main` through :func:`add_parser`. Exit codes follow the
command line's: 0 when the diagnosis ran (whether or not it named effects), 2 for bad input.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path
from typing import Any

from genbacklash_core import Cascade, GenBacklashError
from genbacklash_core.diagnose import (
    AugmentedModel,
    DiagnoseSettings,
    Diagnosis,
    Drift,
    StartStructure,
    diagnose,
    effect_names,
)
from genbacklash_ros.cli.bag_input import (
    add_bag_input_options,
    is_bag,
    load_series,
    servo_dict,
    servo_line,
)
from genbacklash_ros.cli.exit_codes import EXIT_OK
from genbacklash_ros.cli.joints import per_joint
from genbacklash_ros.cli.node_options import (
    BATCH_PARAMETERS,
    CommandParameters,
    add_node_parameter_options,
    batch_parameters,
    node_parameters,
)
from genbacklash_ros.node.parameters import NodeParameters

__all__ = ["add_parser", "cmd_diagnose", "parse_start"]


_DESCRIPTION = """\
Find where a backlash model and the measurements disagree, name the missing effect, add it,
and show the misfit shrink.

DATA is a CSV with header columns u (command) and y (measured position), optional t. The
first part of the record (1 - --validation) is the estimation segment: the starting model -
the ideal backlash of the paper's eq. (1), or --start, or the structure the node parameters
(--params-file, --param) set with model/degree/na/nb - is fitted there. The rest is held out:
the model is simulated free-run over it and the *misfit* is the NRMSE there (unitless; the
*play* is c_L + c_R, in rad). The *floor* is the misfit that quantisation (the readings' grid)
and noise (read off the dwells, where the command stands still) allow; a misfit within 1.3
times it leaves nothing to explain.

For a bag, the samples are the node's: each encoder reading that arrived, with the latest
command at its stamp; a reading whose stamp is not one encoder period after the one before (a
lost reading, a hole in the record) breaks the chain, as in the node, and no fit pairs
samples across it.

Then, in a loop: the estimation residual is tested (Ljung-Box whiteness, prewhitened input
cross-correlation, Billings-Voon higher-order correlations, mean and trend, an FIR
model-error model) and each effect of the catalog looks for its signature:

  {effects}

Nominated effects are added to the model and refitted; the one that lowers the BIC most is
accepted only if it also lowers the validation misfit significantly, judged over two held-out
blocks pooled: the held-out end, and a block as long at the record's start with the models
refitted on the rest. The loop stops when no signature is found or nothing helps; nothing is
named when nothing is missing.
"""

_EPILOG = """\
examples:
  genbacklash diagnose run.csv
  genbacklash diagnose run.csv --json
  genbacklash diagnose run.csv --start degree=3 --report diag/
  genbacklash identify run.csv --degree 3 --json > start.json
  genbacklash diagnose run.csv --start start.json --validation 0.25
  genbacklash diagnose run.csv --param degree=3 --param model=cascade
  genbacklash diagnose run.mcap --command /cmd --encoder /enc --params-file config/params.yaml

--json prints {"steps": [{"effect", "evidence", "misfit_before", "misfit_after"}, ...],
"misfit_initial", "misfit_final", "misfit_floor", "model"} (and, for older tools, the same
numbers as gap_before, gap_after, gap_initial, gap_final, gap_floor); model is the identify
JSON plus delay, offset, drift (rate per sample, rate_per_s when the samples are stamped),
saturation, input_lag, periodic_error and physics (coasting_load, compliant_coupling,
load_torque: the load's motion after the play); misfit_floor is the misfit quantisation and
noise allow (null when not measured). Exit status 0 when the diagnosis ran, 2 for bad input.
"""


def _fraction(text: str) -> float:
    try:
        value = float(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(f"must be a number, got {text!r}") from err
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(f"must be in (0, 1), got {value}")
    return value


def parse_start(text: str) -> StartStructure | AugmentedModel:
    """``degree=N[,na=R,nb=P]`` or the path of an identify/diagnose JSON file.

    >>> parse_start("degree=3,na=2,nb=1")
    StartStructure(degree=3, na=2, nb=1)
    """
    if "=" in text and not Path(text).exists():
        values: dict[str, int] = {}
        for item in text.split(","):
            key, _, value = item.partition("=")
            key = key.strip().lower()
            if key not in ("degree", "na", "nb"):
                raise GenBacklashError(
                    f"--start: unknown key {key!r}; use degree=N[,na=R,nb=P] or a JSON file"
                )
            try:
                values[key] = int(value)
            except ValueError as err:
                raise GenBacklashError(
                    f"--start: {key} must be a whole number, got {value!r}"
                ) from err
        try:  # the node parameters' ranges, as identify's and replay's options take them
            NodeParameters().replace(**values)
        except GenBacklashError as err:
            raise GenBacklashError(f"--start {text}: {err}") from err
        return StartStructure(**values)
    path = Path(text)
    if not path.is_file():
        raise GenBacklashError(
            f"--start: {text} is neither degree=N[,na=R,nb=P] nor an existing JSON file"
        )
    try:
        data: Any = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise GenBacklashError(f"--start: cannot read {path} as JSON: {err}") from err
    if not isinstance(data, dict):
        raise GenBacklashError(f"--start: {path} must hold a JSON object")
    return AugmentedModel.from_dict(data)


def _drift_text(drift: Drift, period: float | None) -> str:
    """The drift rate of each dead zone with its unit: per second where the samples' period
    is known (a bag's stamps, a CSV's t column), else per sample; or per rad of travel.

    >>> _drift_text(Drift(2e-7, "time"), 0.001).strip()
    '0.0002 rad/s (2e-07 rad per sample of 1 ms)'
    """
    if drift.basis == "travel":
        return f"{drift.rate:>12.4g}  rad per rad of command travel"
    if period is None:
        return f"{drift.rate:>12.4g}  rad per sample (no time stamps: a t column gives rad/s)"
    return (
        f"{drift.rate / period:>12.4g} rad/s ({drift.rate:.3g} rad per sample of "
        f"{period * 1e3:.3g} ms)"
    )


def drift_per_second(model: dict[str, Any], period: float | None) -> None:
    """Add ``rate_per_s`` (null when the period is unknown or the basis is travel) to the
    ``drift`` of a diagnose JSON ``model`` (``rate`` stays: per sample or per unit travel)."""
    drift = model.get("drift")
    if isinstance(drift, dict):
        per_s = drift["rate"] / period if period and drift.get("basis") == "time" else None
        drift["rate_per_s"] = per_s


def _model_lines(result: Diagnosis, period: float | None = None) -> list[str]:
    model = result.model
    names = model.base.parameter_names
    values = model.base.parameters()
    lines = [f"  {name:<14}{value:>12.5f}" for name, value in zip(names, values, strict=True)]
    if model.delay:
        lines.append(f"  {'delay':<14}{model.delay:>12d}  samples")
    if model.offset:
        lines.append(f"  {'offset':<14}{model.offset:>12.5f}")
    if model.drift is not None:
        lines.append(f"  {'drift rate':<14}{_drift_text(model.drift, period)}")
    if model.saturation is not None:
        for side in ("low", "high"):
            value = getattr(model.saturation, side)
            if value is not None:
                lines.append(f"  {'limit ' + side:<14}{value:>12.5f}")
    if model.input_lag:
        tau = -1.0 / math.log(model.input_lag)
        stages = f", {model.input_lag_order} equal stages" if model.input_lag_order > 1 else ""
        fraction = model.input_lag_fraction
        late = f", dead time {fraction:g} of a sample longer" if fraction else ""
        lines.append(
            f"  {'input lag':<14}{model.input_lag:>12.5f}  pole ({tau:.1f} samples{stages}{late})"
        )
    if model.periodic is not None:
        periodic = model.periodic
        lines.append(f"  {'period':<14}{periodic.period:>12.5f}")
        for j, amplitude in enumerate(periodic.amplitudes, 1):
            lines.append(f"  {f'harmonic {j}':<14}{amplitude:>12.5f}  amplitude")
    if model.physics is not None:
        for key, value in model.physics.to_dict().items():
            if key == "kind":
                lines.append(f"  {'load physics':<14}{value:>12}")
            elif key == "region":
                lines.append(f"  {key:<14}{value[0]:>12.5f} .. {value[1]:.5f}  load position")
            else:
                lines.append(f"  {key:<14}{value:>12.6g}  {_PHYSICS_UNITS.get(key, '')}")
    return lines


_PHYSICS_UNITS = {
    "retention": "of the free load's velocity kept per sample",
    "friction": "deceleration per sample^2 (Coulomb)",
    "window": "samples (flank velocity)",
    "stiffness": "rad per sample (natural frequency)",
    "damping": "damping ratio",
    "side": "-1: held on the lower flank, +1: the upper",
    "fall": "per sample, at most",
}


def _text(result: Diagnosis, period: float | None = None) -> str:
    split = result.split
    lines = [
        f"estimation samples 0..{split.n_estimation - 1}, validation "
        f"{split.n_estimation}..{split.n_samples - 1}",
        f"starting model: {result.reports[0].describe()}",
    ]
    if result.floor is not None:
        lines.append(f"floor: {result.floor.describe()}")
    for i, step in enumerate(result.steps, 1):
        lines.append(
            f"step {i}: {step.effect} - misfit {step.gap_before:.4f} -> {step.gap_after:.4f}\n"
            f"  {step.evidence}"
        )
    if not result.steps:
        lines.append("no missing effect named")
    lines.append(f"final misfit {result.gap_final:.4f} ({result.reports[-1].describe()})")
    lines.append(f"stopped: {result.reason}")
    if result.unexplained is not None:
        lines.append(result.unexplained_text())
    lines.append(f"final model ({', '.join(result.model.effects) or 'ideal backlash'}):")
    lines += _model_lines(result, period)
    base = result.model.base
    backlash = base.backlash if isinstance(base, Cascade) else base
    lines.append(f"  {'play':<14}{backlash.c_left + backlash.c_right:>12.5f}  rad (c_L + c_R)")
    return "\n".join(lines)


def _start(
    args: argparse.Namespace, cli: CommandParameters
) -> StartStructure | AugmentedModel | None:
    """``--start``, else the structure the node parameters set (any of model, degree, na, nb
    in the params file or a --param: the node's structure, its defaults for the rest), else
    None (the ideal backlash)."""
    if args.start is not None:
        clash = [name for name in BATCH_PARAMETERS if name in cli.overrides]
        if clash:
            raise GenBacklashError(
                f"--start and --param {', '.join(clash)} both set the starting model; give one"
            )
        return parse_start(args.start)
    if not any(name in cli.given for name in BATCH_PARAMETERS):
        return None
    structure = cli.params.structure()
    return StartStructure(structure.degree, structure.na, structure.nb)


def cmd_diagnose(args: argparse.Namespace) -> int:
    """Run the diagnosis for parsed arguments; print text or JSON; write the report."""
    cli = node_parameters(args, batch_parameters(args.data))
    start = _start(args, cli)
    from genbacklash_ros.progress import Progress

    # a line on stderr while it runs (a bar on a terminal, a plain line every few seconds
    # otherwise): a 40 s bag takes tens of seconds
    with Progress("genbacklash diagnose") as progress:
        progress.set_stage(f"reading {args.data}")
        series = load_series(args, cli.params)
        settings = DiagnoseSettings(validation=args.validation)
        result = diagnose(
            series.u,
            series.y,
            start=start,
            settings=settings,
            nonfinite="drop" if args.drop_nonfinite else "raise",
            breaks=series.breaks,
            progress=progress.set_stage,
        )
        written = []
        if args.report:
            from genbacklash_ros.reports.diagnose import write_report

            written = write_report(
                result,
                series.u,
                series.y,
                args.report,
                series.breaks,
                t=series.t,
                unit="rad" if is_bag(args.data) else "units of y",
                progress=progress.set_stage,
            )
    period = series.sample_period()
    if args.json:
        out = result.to_dict()
        drift_per_second(out["model"], period)
        if series.servo is not None:  # servo_model: the input the model saw is its output
            out["servo"] = servo_dict(series)
        print(json.dumps(out))
    else:
        print(_text(result, period))
        if series.servo is not None:
            print(servo_line(series))
    for path in written:
        print(f"wrote {path}", file=sys.stderr)
    return EXIT_OK


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register ``diagnose`` on the ``genbacklash`` subcommand parsers."""
    parser: argparse.ArgumentParser = subparsers.add_parser(
        "diagnose",
        help="find the effect the backlash model misses, add it, show the misfit shrink",
        description=_DESCRIPTION.format(effects="\n  ".join(effect_names())),
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "data",
        metavar="DATA",
        help="CSV file with columns u,y[,t], or a bag (rosbag2 directory or .mcap) with "
        "--command and --encoder",
    )
    add_bag_input_options(parser, required=False)
    parser.add_argument(
        "--json",
        action="store_true",
        help="print one JSON object (the documented contract) instead of text",
    )
    parser.add_argument(
        "--report",
        metavar="DIR",
        help="write plots (measured vs simulated per step, correlations with bounds, the misfit "
        "per step, where the misfit sits), index.html (the page) and summary.md into DIR",
    )
    parser.add_argument(
        "--start",
        metavar="MODEL",
        help="starting model: degree=N[,na=R,nb=P] to identify that structure, or a JSON "
        "file written by 'identify --json' or 'diagnose --json' (default: the ideal "
        "backlash, degree=1)",
    )
    parser.add_argument(
        "--validation",
        type=_fraction,
        default=0.3,
        metavar="FRACTION",
        help="fraction of the record held out at its end for the misfit (default 0.3)",
    )
    parser.add_argument(
        "--drop-nonfinite",
        action="store_true",
        help="drop NaN/inf samples instead of stopping with an error",
    )
    add_node_parameter_options(
        parser,
        used="diagnose uses model, degree, na, nb as the starting structure when any of them "
        "is set and --start is not (the node's defaults for the rest), and, for a bag, joint, "
        "command_index; the others are validated, then ignored (a note on stderr names those "
        "set to other than their defaults).",
    )
    parser.set_defaults(
        func=per_joint(cmd_diagnose, data="data", dirs=("report",), report="report")
    )
    return parser
