"""A planned bag analysed joint by joint (:func:`analyse_bag`): identified, diagnosed and,
optionally, replayed; never raising for a bad bag.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from genbacklash_core import (
    Cascade,
    GenBacklashError,
    IdentificationResult,
    identify_backlash,
    identify_cascade,
)
from genbacklash_core.cascade import model_to_dict
from genbacklash_core.diagnose import DiagnoseSettings, StartStructure, diagnose
from genbacklash_core.errors import NotEnoughExcitationError
from genbacklash_core.uncertainty import parameter_covariance, play_std
from genbacklash_ros.bags.bagio import (
    AlignedSeries,
    BagError,
    read_aligned,
)
from genbacklash_ros.fleet.archive import (
    recorded_duration_ns,
)
from genbacklash_ros.node.parameters import NodeParameters

from .plan import BagPlan
from .result import BagResult
from .settings import FleetSettings


def _identify(
    params: NodeParameters, u: np.ndarray, y: np.ndarray, breaks: np.ndarray
) -> IdentificationResult:
    if params.model == "cascade":
        return identify_cascade(u, y, params.degree, params.na, params.nb, breaks=breaks)
    return identify_backlash(u, y, params.degree, breaks=breaks)


def _fit_fields(
    result: IdentificationResult, u: np.ndarray, y: np.ndarray, breaks: np.ndarray
) -> dict[str, Any]:
    model = result.model
    backlash = model.backlash if isinstance(model, Cascade) else model
    cov = parameter_covariance(model, u, y, breaks)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    names = model.parameter_names
    index = {name: i for i, name in enumerate(names)}
    return {
        "model": "cascade" if isinstance(model, Cascade) else "backlash",
        "degree": backlash.degree,
        "c_left": float(backlash.c_left),
        "c_left_std": float(std[index["c_left"]]),
        "c_right": float(backlash.c_right),
        "c_right_std": float(std[index["c_right"]]),
        "gap": float(backlash.c_left + backlash.c_right),
        "gap_std": play_std(model, cov),
        "parameters": dict(zip(names, map(float, model.parameters()), strict=True)),
        "parameter_std": dict(zip(names, map(float, std), strict=True)),
        "estimate": model_to_dict(model),
        "nrmse": float(result.fit.nrmse),
        "iterations": int(result.iterations),
        "converged": bool(result.converged),
        "reason": result.reason,
    }


def truncation_note(read_s: float | None, recorded_s: float | None) -> str:
    """The flag of a cut recording whose readable part was used.

    >>> truncation_note(4.46, 9.9993), truncation_note(4.46, None)
    ('truncated: read 4.5 of 10.0 s', 'truncated: read 4.5 s (the rest is lost)')
    """
    read = "?" if read_s is None else f"{read_s:.1f}"
    if recorded_s is None:
        return f"truncated: read {read} s (the rest is lost)"
    return f"truncated: read {read} of {recorded_s:.1f} s"


def _replay_fields(
    path: Path, settings: FleetSettings, joint: str, command_index: int
) -> dict[str, Any]:
    from genbacklash_ros.bags.replay import replay

    with tempfile.TemporaryDirectory(prefix="genbacklash-fleet-") as tmp:
        result = replay(
            path,
            Path(tmp) / "out",
            command_topic=settings.command_topic,
            encoder_topic=settings.encoder_topic,
            params=settings.params,
            joint=joint,
            command_index=command_index,
        )
    est = result.estimate
    summary = {k: v for k, v in result.to_dict().items() if k != "output"}
    fields: dict[str, Any] = {"replay": summary, "replay_state": est.state.value}
    if est.model is not None:
        play, play_std = est.play()
        fields["replay_gap"] = play
        fields["replay_gap_std"] = play_std
    if result.error:
        summary["error"] = result.error
    return fields


def _analyse_joint(
    plan: BagPlan, settings: FleetSettings, joint: str, command_index: int
) -> dict[str, Any]:
    """The measured columns of one joint (raises for a bag or data that cannot be used)."""
    series = read_aligned(
        plan.bag.path,
        settings.command_topic,
        settings.encoder_topic,
        joint=joint,
        command_index=command_index,
        keep_readable=True,  # a cut recording: its readable part, flagged (as replay keeps it)
    )
    out: dict[str, Any] = {
        "n_samples": int(series.u.size),
        "duration_s": float((series.t[-1] - series.t[0]) / 1e9) if series.t.size else 0.0,
        "truncated": bool(series.damage),
    }
    flag = ""
    if series.damage:
        recorded = recorded_duration_ns(plan.bag.path)
        out["recorded_s"] = None if recorded is None else recorded / 1e9
        flag = f"{truncation_note(out['duration_s'], out['recorded_s'])} ({series.damage})"
    try:
        out.update(_measure(plan, settings, joint, command_index, series))
    except Exception as err:  # the row keeps what was read, and the flag
        out["status"], out["reason"] = _status_of(err)
    if flag:
        out["reason"] = f"{flag}; {out['reason']}"
    return out


def _measure(
    plan: BagPlan,
    settings: FleetSettings,
    joint: str,
    command_index: int,
    series: AlignedSeries,
) -> dict[str, Any]:
    """Identify, diagnose and replay one joint's aligned samples (raises for data that
    cannot be used)."""
    out: dict[str, Any] = {}
    result = _identify(settings.params, series.u, series.y, series.breaks)
    out.update(_fit_fields(result, series.u, series.y, series.breaks))
    out["status"] = "ok" if result.converged else "not_converged"
    if result.converged and not out["nrmse"] <= settings.max_nrmse:
        out["status"] = "poor_fit"
        out["reason"] = (
            f"free-run NRMSE {out['nrmse']:.3g} is above max_nrmse {settings.max_nrmse:g}: "
            f"the estimate is not trusted; {out['reason']}"
        )
    if settings.diagnose:
        start = None
        if settings.diagnose_from_params:
            s = settings.params.structure()
            start = StartStructure(s.degree, s.na, s.nb)
        try:
            found = diagnose(
                series.u,
                series.y,
                start=start,
                settings=DiagnoseSettings(validation=settings.validation),
                breaks=series.breaks,
            )
        except GenBacklashError as err:
            out["reason"] = f"{out['reason']}; diagnose: {err}".lstrip("; ")
        else:
            out["diagnosis"] = found.to_dict()
            out["diagnose_effects"] = ",".join(step.effect for step in found.steps)
            out["diagnose_gap_initial"] = float(found.gap_initial)
            out["diagnose_gap_final"] = float(found.gap_final)
    if settings.replay:
        out.update(_replay_fields(plan.bag.path, settings, joint, command_index))
    return out


def _status_of(err: Exception) -> tuple[str, str]:
    if isinstance(err, NotEnoughExcitationError):
        return "no_motion", str(err)
    if isinstance(err, BagError):
        return "unreadable", str(err)
    if isinstance(err, GenBacklashError):
        return "failed", str(err)
    return "failed", f"{type(err).__name__}: {err}"


def analyse_bag(plan: BagPlan, settings: FleetSettings) -> tuple[BagResult, ...]:
    """One :class:`BagResult` per joint of ``plan`` (see the module notes); never raises for
    a bad bag."""
    common: dict[str, Any] = {
        "bag_hash": plan.bag_hash,
        "robot": plan.robot,
        "bag_path": plan.bag.relpath,
        "recorded_ns": plan.recorded_ns,
        "time_source": plan.time_source,
    }
    if plan.reason:
        return (
            BagResult(
                joint="",
                settings_key=settings.key("", settings.params.command_index),
                status="unreadable",
                reason=plan.reason,
                settings=settings.to_dict("", settings.params.command_index),
                **common,
            ),
        )
    results = []
    for joint, index in plan.joints:
        started = time.perf_counter()
        try:
            fields = _analyse_joint(plan, settings, joint, index)
        except Exception as err:  # a bad bag is a row, never a lost archive
            status, reason = _status_of(err)
            fields = {"status": status, "reason": reason}
        results.append(
            BagResult(
                joint=joint,
                settings_key=settings.key(joint, index),
                command_index=index,
                settings=settings.to_dict(joint, index),
                compute_s=time.perf_counter() - started,
                **common,
                **fields,
            )
        )
    return tuple(results)
