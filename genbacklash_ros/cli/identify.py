"""``genbacklash identify``: batch identification of a recording (a CSV or a bag), with the
parameters' standard deviations, a summary line, and optionally plots and a checkpoint for
the node's start; the paper-example ``demo`` prints the same table.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence

import numpy as np

from genbacklash_core import (
    Cascade,
    GenBacklashError,
    GeneralBacklash,
    IdentificationResult,
    identify_backlash,
    identify_cascade,
)
from genbacklash_core.data import NonFinitePolicy
from genbacklash_core.uncertainty import batch_uncertainty, play_std
from genbacklash_ros.bags.csvio import Series
from genbacklash_ros.cli import bag_input as bag_input_cli
from genbacklash_ros.cli import node_options as node_options_cli
from genbacklash_ros.cli import replay as replay_cli
from genbacklash_ros.cli.exit_codes import EXIT_NOT_CONVERGED, EXIT_OK
from genbacklash_ros.progress import Progress

__all__ = ["Uncertainty", "cmd_identify", "identify", "parameter_table", "summary"]


def identify(
    series: Series,
    *,
    model: str,
    degree: int,
    na: int = 2,
    nb: int = 2,
    sign: float | None = None,
    refine: bool = True,
    max_iterations: int = 30,
    nonfinite: NonFinitePolicy = "raise",
    show_progress: bool = True,
) -> IdentificationResult:
    """Run the identifier chosen by ``model`` with a progress bar over the iterations."""
    progress = Progress(
        "genbacklash identify", total=max_iterations, unit="it", enabled=show_progress
    )

    def step(iteration: int, parameters: np.ndarray) -> None:
        progress.update(1)

    try:
        if model == "cascade":
            return identify_cascade(
                series.u,
                series.y,
                degree,
                na,
                nb,
                sign=sign,
                refine=refine,
                max_iterations=max_iterations,
                nonfinite=nonfinite,
                callback=step,
                breaks=series.breaks,
            )
        return identify_backlash(
            series.u,
            series.y,
            degree,
            sign=sign,
            refine=refine,
            max_iterations=max_iterations,
            nonfinite=nonfinite,
            callback=step,
            breaks=series.breaks,
            restart_holds=True,  # a load moving on inside the play: genbacklash_core.identify
        )
    finally:
        progress.close()


class Uncertainty:
    """The batch estimate's standard deviations in two parts
    (:func:`genbacklash_core.uncertainty.batch_uncertainty`): the statistical one, the
    output-error fit's Gauss-Newton covariance ``s^2 (J^T J)^-1``, and the model error's, from
    the misfit white noise does not explain (:mod:`genbacklash_core.model_error`); the total
    is their root sum of squares. Each is propagated to the play ``c_L + c_R`` by its
    gradient. NaN where the data do not tell."""

    def __init__(self, result: IdentificationResult, series: Series) -> None:
        model = result.model
        size = len(model.parameter_names)
        self.misfit = math.nan
        try:
            spread = batch_uncertainty(model, series.u, series.y, series.breaks)
            parts = {"": spread.total, "statistical": spread.statistical, "model": spread.model}
            self.parts = {k: np.sqrt(np.maximum(np.diag(c), 0.0)) for k, c in parts.items()}
            self.play_parts = {k: play_std(model, c) for k, c in parts.items()}
            self.misfit = spread.misfit.rms_model
        except (GenBacklashError, ValueError, FloatingPointError, np.linalg.LinAlgError):
            self.parts = {k: np.full(size, np.nan) for k in ("", "statistical", "model")}
            self.play_parts = {k: math.nan for k in ("", "statistical", "model")}
        self.std = self.parts[""]
        self.play_std = self.play_parts[""]
        backlash = model.backlash if isinstance(model, Cascade) else model
        self.play = float(backlash.c_left + backlash.c_right)

    @property
    def model_dominates(self) -> bool:
        """Whether the play's model-error part is larger than its statistical part."""
        return bool(self.play_parts["model"] > self.play_parts["statistical"])

    def to_dict(self, names: Sequence[str]) -> dict[str, object]:
        """``play_std`` and ``parameter_std`` (name -> std; the total) for the JSON, with
        their ``_statistical`` and ``_model`` parts, ``model_error_dominates`` and
        ``misfit_correlated`` (the RMS misfit the model term comes from, in the units of
        ``y``); None where unknown."""

        def clean(value: float) -> float | None:
            return float(value) if math.isfinite(value) else None

        out: dict[str, object] = {}
        for part, std in self.parts.items():
            suffix = f"_{part}" if part else ""
            out[f"play_std{suffix}"] = clean(self.play_parts[part])
            out[f"parameter_std{suffix}"] = {
                n: clean(v) for n, v in zip(names, std.tolist(), strict=True)
            }
        out["model_error_dominates"] = self.model_dominates
        out["misfit_correlated"] = clean(self.misfit)
        return out

    def lines(self) -> list[str]:
        """The play with its 2-sigma band, and how the band splits (text output)."""
        out = [replay_cli.play_line(self.play, self.play_std)]
        stat, model = self.play_parts["statistical"], self.play_parts["model"]
        if not (math.isfinite(stat) and math.isfinite(model)):
            return out
        out.append(
            f"  of which (2 sigma) statistical +/- {2 * stat:.5f} rad, model error +/- "
            f"{2 * model:.5f} rad"
        )
        if self.model_dominates:
            out.append(
                f"  the model error dominates: {self.misfit:.3g} RMS of the misfit follows "
                "the motion (not white noise):\n  the play operator does not describe this "
                "record fully (a servo's lag, a coasting load, a spring,\n  gravity, a play "
                "that wears during the record, the encoder's rounding while the load rests);"
                "\n  the band is the bias a misfit that size can cause"
            )
        if math.isfinite(self.play_std) and 2 * self.play_std > abs(self.play):
            out.append("  the band is wider than the play itself: the play is not determined")
        return out


RAD = replay_cli.RAD_PARAMETERS


def parameter_table(
    result: IdentificationResult,
    truth: GeneralBacklash | Cascade | None = None,
    std: np.ndarray | None = None,
) -> str:
    names = result.model.parameter_names
    estimate = result.model.parameters()
    header = f"{'parameter':<12}{'estimate':>12}"
    if std is not None:
        header += f"{'2 sigma':>12}"
    true_values = None
    if truth is not None:
        true_values = truth.parameters()
        header += f"{'truth':>12}{'error':>12}"
    lines = [header, "-" * len(header)]
    for i, name in enumerate(names):
        row = f"{name:<12}{estimate[i]:>12.5f}"
        if std is not None:
            row += f"{2 * std[i]:>12.5f}"
        if true_values is not None:
            row += f"{true_values[i]:>12.5f}{estimate[i] - true_values[i]:>+12.5f}"
        if name in RAD:
            row += "  rad"
        lines.append(row)
    return "\n".join(lines)


def summary(result: IdentificationResult) -> str:
    status = "converged" if result.converged else "NOT converged"
    return (
        f"{status} after {result.iterations} iterations; free-run misfit (NRMSE) "
        f"{result.fit.nrmse:.4f}\n{result.reason}"
    )


def cmd_identify(args: argparse.Namespace) -> int:
    params = node_options_cli.node_parameters(
        args, node_options_cli.batch_parameters(args.data)
    ).params
    model = params.model if args.model is None else args.model
    # a backlash alone is rate independent: lost readings along monotone commands hide nothing
    series = bag_input_cli.load_series(args, params, bridge=model == "backlash")
    result = identify(
        series,
        model=model,
        degree=params.degree if args.degree is None else args.degree,
        na=params.na if args.na is None else args.na,
        nb=params.nb if args.nb is None else args.nb,
        sign=None if args.sign == "auto" else float(args.sign),
        refine=not args.no_refine,
        max_iterations=args.max_iterations,
        nonfinite="drop" if args.drop_nonfinite else "raise",
        show_progress=not args.json,
    )
    spread = Uncertainty(result, series)
    if args.json:
        out = result.to_dict()
        out.update(spread.to_dict(result.model.parameter_names))
        if series.servo is not None:  # the servo the rows model (genbacklash_core.servo)
            out["servo"] = bag_input_cli.servo_dict(series)
        print(json.dumps(out))
    else:
        print(parameter_table(result, std=spread.std))
        print("\n".join(spread.lines()))
        if series.servo is not None:
            print(bag_input_cli.servo_line(series))
        print(summary(result))
    if args.checkpoint:
        from genbacklash_ros.cli.start import identify_estimate, write_start

        stamps = series.t
        time_ns = round(float(stamps[-1]) * 1e9) if stamps is not None and stamps.size else 0
        estimate = identify_estimate(result, series)
        write_start(args.checkpoint, estimate, time_ns, "identify", series.baseline)
    if args.plot:
        from genbacklash_ros.reports.plots import save_identification_plots

        unit = "rad" if bag_input_cli.is_bag(args.data) else ""  # a CSV says no unit
        for path in save_identification_plots(result, args.plot, series.u, series.y, unit=unit):
            print(f"wrote {path}", file=sys.stderr)
    return EXIT_OK if result.converged else EXIT_NOT_CONVERGED
