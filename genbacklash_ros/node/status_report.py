"""The node's ``/diagnostics`` status: its level, message and values, from the stages' reports.

:meth:`~genbacklash_ros.node.pipeline.BacklashPipeline.diagnostics` asks each stage for its
part of a report -- the faults (:meth:`~genbacklash_ros.node.health.StreamHealth.report`),
the silent streams (:meth:`~genbacklash_ros.node.silence.SilentStreams.report`), the drops
and problems since the last report (:meth:`~genbacklash_ros.node.ledger.Ledger.take_period`),
the compensator's state (:meth:`~genbacklash_ros.node.compensate.CompensateStage.status`) --
and :func:`status_output` puts them into one ``DiagnosticArray`` (GUIDE §4: state,
confidence, residual, excitation, every parameter, and the node's own values). It changes
no state: the reports that reset per-report counts are taken by the pipeline, in its order.

The level is the highest of: the estimate's state (OK converging or converged, WARN warming
up, ERROR diverged), the active faults, the silent streams, WARN for messages dropped or
problems since the last report, for compensation held off by the guard or the measured
tracking, or for a judge that cannot measure (``compensation_in_loop``); STALE when the
transport's watchdog saw no data.
"""

from __future__ import annotations

import math

from genbacklash_core import Estimate
from genbacklash_core.guard import GuardVerdict
from genbacklash_core.measured import TrackingVerdict
from genbacklash_ros.node.align import Aligner
from genbacklash_ros.node.compensate import CompensationStatus
from genbacklash_ros.node.health import HealthReport
from genbacklash_ros.node.identify import EstimateInUse
from genbacklash_ros.node.ledger import QUIET_DROPS, SHOWN_WHEN_ANY, Ledger, Period
from genbacklash_ros.node.messages import DiagnosticStatus, diagnostic_array, level_of
from genbacklash_ros.node.outputs import Output
from genbacklash_ros.node.silence import SilenceReport

__all__ = ["servo_summary", "status_output"]


def servo_summary(align: Aligner, window: float) -> dict[str, object]:
    """What the alignment knows of the servo the identifier's input goes through (see
    :attr:`~genbacklash_ros.node.pipeline.BacklashPipeline.servo`); ``window`` is the
    ``servo_window`` parameter (s), reported while estimating."""
    model, fit = align.servo, align.servo_fit
    if align.servo_pending:
        return {"state": "estimating", "window": window}
    assert model is not None
    out: dict[str, object] = dict(model.to_dict())
    if align.servo_note:
        out.update(state="none", note=align.servo_note)
    elif fit is not None:
        out.update(state="estimated", misfit=fit.misfit, misfit_without=fit.none_misfit)
    else:
        out["state"] = "fixed"
    return out


def status_output(
    stamp_ns: int,
    est: Estimate,
    *,
    use: EstimateInUse,
    health: HealthReport,
    silent: SilenceReport,
    period: Period,
    ledger: Ledger,
    guard: GuardVerdict,
    measured: TrackingVerdict,
    status: CompensationStatus,
    compensate: bool,
    await_guard: bool,
    warm_start_note: str,
    servo: dict[str, object] | None,
    name: str,
    hardware_id: str,
    stale: bool = False,
) -> Output:
    """The ``diagnostics`` output at ``stamp_ns`` for the estimate in use ``est``.

    Parameters
    ----------
    stamp_ns : int
        Data time of the report.
    est : Estimate
        The estimate in use (its state, confidence, residual, excitation and parameters).
    use : EstimateInUse
        Where ``est`` comes from (the checkpoint or the identifier) and the identifier's own.
    health, silent, period : HealthReport, SilenceReport, Period
        The faults, the silent streams, the drops and problems since the last report.
    ledger : Ledger
        The counters since construction.
    guard, measured : GuardVerdict, TrackingVerdict
        The compensation guard's and the measured tracking's latest verdicts.
    status : CompensationStatus
        How much the next command is compensated, and why.
    compensate : bool
        The ``compensate`` parameter.
    await_guard : bool
        A checkpoint's model waits for the guard's first verdict on this machine's samples.
    warm_start_note : str
        What the start made of the checkpoint file ("" when none was used).
    servo : dict or None
        :func:`servo_summary` (None with ``servo_model`` none).
    name, hardware_id : str
        The status's name and hardware id (the joint).
    stale : bool
        Level STALE, "no data" first (a transport's wall-clock watchdog).

    Returns
    -------
    Output
        Topic ``diagnostics``, with ``est`` attached.
    """
    level = level_of(est.state)
    parts = [f"{est.state.value}: {est.reason}" if est.reason else est.state.value]
    if use.on_prior:
        parts.insert(0, "using the checkpoint's estimate until the identifier converges")
    elif use.using_checkpoint:
        parts.insert(0, "continuing from the checkpoint's estimate")
    level = max(level, health.level)
    parts.extend(health.parts)
    if silent.parts:
        level = max(level, silent.level)
        parts.extend(silent.parts)
    loud = {k: n for k, n in period.drops.items() if k not in QUIET_DROPS}
    if loud:
        level = max(level, DiagnosticStatus.WARN)
        listed = "; ".join(
            f"{n} {k.replace('_', ' ')} (last: {period.reasons[k]})" for k, n in loud.items()
        )
        parts.append(f"dropped since the last report: {listed}")
    if period.problems:
        level = max(level, DiagnosticStatus.WARN)
        parts.extend(period.problems)
    if await_guard and est.available and compensate:
        parts.append(
            "compensation held off until the guard has judged the checkpoint's model on "
            "this machine's samples"
        )
    if est.available and compensate and guard.state in ("faded", "off"):
        parts.append(guard.reason)
        if guard.state == "off":
            level = max(level, DiagnosticStatus.WARN)
    if est.available and compensate and measured.state in ("faded", "off"):
        parts.append(measured.reason)
        if measured.state == "off":
            level = max(level, DiagnosticStatus.WARN)
    if measured.state == "watching" and "compensation_in_loop true" in measured.reason:
        parts.append(measured.reason)  # the compensated command drives the drivetrain
        level = max(level, DiagnosticStatus.WARN)
    if stale:
        level = DiagnosticStatus.STALE
        parts.insert(0, "no data")
    source = "checkpoint" if use.using_checkpoint else "identifier"
    own = use.own
    extra = [
        ("estimate_source", source if est.available else "none"),
        ("identifier_state", own.state.value),
        ("identifier_confidence", format(own.confidence, ".3g")),
        ("compensation_weight", format(status.weight, ".3g")),
        ("compensation_state", status.state),
        ("compensation_reason", status.reason),
        ("compensation_guard", guard.state),
        ("compensation_trust", format(guard.trust, ".3g")),
        ("guard_error_ratio", format(guard.ratio, ".3g") if guard.ratio < math.inf else "none"),
        ("measured_tracking", measured.state),
        (
            "measured_tracking_baseline",
            "offline baseline from the checkpoint"
            if measured.baseline == "offline"
            else "measured",
        ),
        (
            "measured_tracking_ratio",
            format(measured.ratio, ".3g") if math.isfinite(measured.ratio) else "none",
        ),
        ("faults", ",".join(health.active) or "none"),
        ("commands", str(ledger.commands)),
        ("encoder_messages", str(ledger.encoders)),
        ("compensated_commands", str(ledger.compensated)),
        ("identifier_samples", str(ledger.samples)),
        ("checkpoints", str(ledger.checkpoints)),
        ("checkpoint_errors", str(ledger.checkpoint_errors)),
    ]
    extra += [
        (f"dropped_{k}", str(n)) for k, n in ledger.dropped.items() if n or k not in SHOWN_WHEN_ANY
    ]
    extra += silent.values
    saved = ledger.last_checkpoint_ns
    extra.append(("last_checkpoint_s", "none" if saved is None else f"{saved / 1e9:.3f}"))
    if warm_start_note:
        extra.append(("warm_start", warm_start_note))
    if servo is not None:  # the servo model the identifier's input goes through
        extra.append(("servo_state", str(servo["state"])))
        for key in ("dead_time", "time_constant"):
            if key in servo:
                extra.append((f"servo_{key}", format(float(servo[key]), ".6g")))  # type: ignore[arg-type]
        if "note" in servo:
            extra.append(("servo_note", str(servo["note"])))
    message = diagnostic_array(
        stamp_ns,
        est,
        level=level,
        message="; ".join(parts),
        name=name,
        hardware_id=hardware_id,
        extra=extra,
    )
    return Output("diagnostics", message, stamp_ns, est)
