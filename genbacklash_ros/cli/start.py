"""From an offline result to the node's start: ``--checkpoint FILE`` of identify and replay.

The node (:class:`~genbacklash_ros.node.pipeline.BacklashPipeline`) warm-starts from the file
its ``checkpoint_file`` parameter names (:func:`~genbacklash_ros.node.checkpoint.warm_start`).
``genbacklash identify --checkpoint FILE`` and ``genbacklash replay --checkpoint FILE`` write
their final estimate there, with :func:`~genbacklash_ros.node.checkpoint.save_checkpoint` (the
node's own writer: one format, one serialiser). The node takes it when its ``model``,
``degree``, ``na`` and ``nb`` match the file's structure; otherwise it starts cold and says
why. :func:`node_settings` is what to give the node.

identify's estimate carries a covariance like the online identifiers' (the least-squares
``sigma^2 (Phi^T Phi)^-1`` of eq. 23/33 at the identified parameters, carried to the natural
parameters by the delta method), so the node's identifier is *seeded* with it and continues
from it. Where that regression is singular the file still holds the parameters: the node then
compensates with them until its identifier converges (its note says so).

The file also holds the record's tracking without compensation (the checkpoint's
``baseline``: :func:`~genbacklash_ros.node.tracking_stage.record_baseline`, what the node's
measured-tracking judge measures as its baseline) when the record had none in it: a bag
without the node's outputs (:func:`~genbacklash_ros.bags.bagio.node_outputs`), replayed
without ``compensation_in_loop``. A CSV cannot tell, and gets none. The node's judge then
starts from it: compensation is tried once the node's guard has judged the model on the
machine's own samples (about 1-2 s) instead of after 3 s of tracking without it, and the live
baseline replaces the stored one after half a second of it (:mod:`genbacklash_core.measured`,
:mod:`genbacklash_ros.node.pipeline`).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

from genbacklash_core import Estimate, GenBacklashError, IdentificationResult, Structure
from genbacklash_core.estimate import EstimatorState, confidence_of, relative_std
from genbacklash_core.measured import OfflineBaseline
from genbacklash_core.online.covariance import natural_covariance
from genbacklash_core.online.fits import solve_normal
from genbacklash_core.online.rows import window_rows
from genbacklash_core.online.settings import WindowedSettings
from genbacklash_ros.bags.csvio import Series
from genbacklash_ros.node.checkpoint import Checkpoint, CheckpointError, save_checkpoint

__all__ = [
    "CHECKPOINT_HELP",
    "add_checkpoint_option",
    "identify_estimate",
    "node_settings",
    "write_start",
]

CHECKPOINT_HELP = (
    "also write the final estimate to FILE in the node's checkpoint format (the file its "
    "checkpoint_file parameter names): the node starts from it when its model, degree, na and "
    "nb match (the line on stderr says which to set). The --json output is not that format"
)


def add_checkpoint_option(parser: argparse.ArgumentParser) -> None:
    """``--checkpoint FILE`` (``args.checkpoint``)."""
    parser.add_argument("--checkpoint", metavar="FILE", default=None, help=CHECKPOINT_HELP)


def _covariance(
    structure: Structure, p: np.ndarray, series: Series
) -> tuple[np.ndarray, float, float]:
    """``(covariance, residual, excitation)`` of ``p`` on the data: the regression of eq.
    (24)/(35) at ``p``, its least-squares covariance carried to the natural parameters; NaN
    covariance (and residual) where the regression is singular."""
    size = structure.n_parameters
    nan = np.full((size, size), np.nan)
    u, y = series.u, series.y
    finite = np.isfinite(u) & np.isfinite(y)
    if not finite.all():  # identify --drop-nonfinite: the rows of the kept samples
        u, y = u[finite], y[finite]
    breaks = series.breaks[finite] if series.breaks is not None else None
    if u.size < 3:
        return nan, math.nan, 0.0
    deadband = WindowedSettings().input_deadband * float(np.ptp(u))
    try:
        rows = window_rows(structure, p, u, y, deadband, breaks=breaks)
    except (GenBacklashError, ValueError, FloatingPointError):
        return nan, math.nan, 0.0
    excitation = float(rows.informative.mean()) if rows.informative.size else 0.0
    m = rows.target.size
    solved = solve_normal(rows.phi, rows.target) if m > size else None
    if solved is None:
        return nan, math.nan, excitation
    _, inverse = solved
    theta = structure.theta(p)
    error = rows.target - rows.phi @ theta  # the equation error at the identified parameters
    rss = float(error @ error)
    sigma2 = rss / max(m - size, 1)
    covariance = natural_covariance(structure, theta, sigma2 * inverse)
    if not np.all(np.isfinite(covariance)):
        return nan, math.nan, excitation
    return covariance, math.sqrt(rss / m), excitation


def identify_estimate(result: IdentificationResult, series: Series) -> Estimate:
    """identify's result as an :class:`~genbacklash_core.Estimate`, the form the node's
    checkpoint holds: the model's parameters, their covariance on ``series``, the state
    ``converged`` (or ``converging`` when the identification did not converge)."""
    structure = Structure.of(result.model)
    p = np.asarray(result.model.parameters(), dtype=np.float64)
    covariance, residual, excitation = _covariance(structure, p, series)
    state = EstimatorState.CONVERGED if result.converged else EstimatorState.CONVERGING
    rel = relative_std(p, covariance) if np.all(np.isfinite(covariance)) else math.inf
    confidence = confidence_of(state, rel, WindowedSettings().converged_std)
    if not math.isfinite(rel):  # no uncertainty: the parameters alone, trusted as converging
        confidence = 0.5 if result.converged else 0.25
    return Estimate(
        structure,
        p,
        covariance,
        residual,
        min(max(excitation, 0.0), 1.0),
        state,
        confidence,
        int(series.u.size),
        f"batch identification: {result.reason}",
    )


def node_settings(estimate: Estimate) -> str:
    """The node parameters that must match the estimate's structure, as ``name=value``."""
    s = estimate.structure
    if s.cascade:
        return f"model=cascade degree={s.degree} na={s.na} nb={s.nb}"
    return f"model=backlash degree={s.degree}"


def write_start(
    path: str | Path,
    estimate: Estimate,
    time_ns: int,
    command: str,
    baseline: OfflineBaseline | None = None,
) -> None:
    """Save ``estimate`` (and the record's tracking without compensation, ``baseline``,
    when measured) as the node's checkpoint at ``path`` and say on stderr how the node
    takes it; :class:`GenBacklashError` when there is no estimate to save."""
    if estimate.model is None:
        raise GenBacklashError(
            f"--checkpoint {path}: no valid estimate to write ({estimate.state.value}: "
            f"{estimate.reason or 'no parameters'}); nothing written"
        )
    try:
        save_checkpoint(path, Checkpoint(estimate, int(time_ns), baseline=baseline))
    except CheckpointError as err:
        raise GenBacklashError(f"--checkpoint: {err}") from err
    if baseline is not None:
        tracking = (
            f"; with the record's tracking without compensation ({1e3 * baseline.rms:.3g} "
            f"mrad rms over {baseline.seconds:.0f} s) as the measured-tracking baseline"
        )
    else:
        tracking = (
            "; no tracking baseline stored (a CSV, a record with the node's outputs in it, "
            "or under 3 s of it)"
        )
    print(
        f"genbacklash {command}: wrote checkpoint {path}{tracking}; the node starts from it "
        f"with checkpoint_file={path} {node_settings(estimate)}",
        file=sys.stderr,
    )
