"""The /diagnostics status built from the stages' reports (genbacklash_ros.node.status_report)."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from genbacklash_core import Estimate, Structure
from genbacklash_core.guard import CompensationGuard
from genbacklash_core.measured import TrackingJudge
from genbacklash_ros.node.align import Aligner
from genbacklash_ros.node.compensate import CompensationStatus
from genbacklash_ros.node.health import HealthReport
from genbacklash_ros.node.identify import EstimateInUse
from genbacklash_ros.node.ledger import Ledger, Period
from genbacklash_ros.node.messages import DiagnosticArray, DiagnosticStatus
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.silence import SilenceReport
from genbacklash_ros.node.status_report import servo_summary, status_output

PARAMS = NodeParameters()


def report(**changes: Any) -> tuple[int, str, dict[str, str]]:
    """(level, message, values) of a status built from quiet stage reports and ``changes``."""
    est = Estimate.empty(Structure(3))
    kwargs: dict[str, Any] = dict(
        use=EstimateInUse(est, prior=None, from_seed=False),
        health=HealthReport(False, DiagnosticStatus.OK, [], ()),
        silent=SilenceReport(DiagnosticStatus.OK, [], []),
        period=Period(),
        ledger=Ledger(),
        guard=CompensationGuard(PARAMS.guard_settings()).verdict,
        measured=TrackingJudge(PARAMS.judge_settings()).verdict,
        status=CompensationStatus(0.0, "off", "no estimate yet"),
        compensate=True,
        await_guard=False,
        warm_start_note="",
        servo=None,
        name="backlash_identifier",
        hardware_id="j",
    )
    kwargs.update(changes)
    out = status_output(5_000_000_000, est, **kwargs)
    assert out.topic == "diagnostics" and out.stamp_ns == 5_000_000_000 and out.estimate is est
    assert isinstance(out.message, DiagnosticArray)
    (status,) = out.message.status
    assert status.name == "backlash_identifier" and status.hardware_id == "j"
    return status.level, status.message, {kv.key: kv.value for kv in status.values}


def test_quiet_stages_report_the_estimate_state_alone() -> None:
    level, message, values = report()
    assert level == DiagnosticStatus.WARN  # warming up, nothing else to say
    assert "dropped" not in message and "no data" not in message
    assert values["estimate_source"] == "none" and values["faults"] == "none"
    assert values["last_checkpoint_s"] == "none" and "warm_start" not in values


def test_stale_comes_first_at_level_stale() -> None:
    level, message, _ = report(stale=True)
    assert level == DiagnosticStatus.STALE and message.startswith("no data; ")


def test_loud_drops_and_problems_warn_quiet_ones_do_not() -> None:
    period = Period({"command_invalid": 2}, {"command_invalid": "not finite"}, ["a problem"])
    level, message, _ = report(period=period)
    assert level == DiagnosticStatus.WARN
    assert "dropped since the last report: 2 command invalid (last: not finite)" in message
    assert message.endswith("; a problem")


def test_faults_and_silence_raise_the_level() -> None:
    health = HealthReport(True, DiagnosticStatus.ERROR, ["passing through"], ("encoder_stuck",))
    silent = SilenceReport(DiagnosticStatus.WARN, ["commands silent"], [("command_silent_s", "3")])
    level, message, values = report(health=health, silent=silent)
    assert level == DiagnosticStatus.ERROR
    assert "passing through; commands silent" in message
    assert values["faults"] == "encoder_stuck" and values["command_silent_s"] == "3"


def test_counters_warm_start_and_servo_values() -> None:
    ledger = Ledger()
    ledger.commands, ledger.last_checkpoint_ns = 7, 2_500_000_000
    servo = {"state": "estimated", "dead_time": 0.004, "time_constant": 0.02, "note": "n"}
    _, _, values = report(ledger=ledger, warm_start_note="fresh start", servo=servo)
    assert values["commands"] == "7" and values["last_checkpoint_s"] == "2.500"
    assert values["warm_start"] == "fresh start"
    assert values["servo_state"] == "estimated" and values["servo_dead_time"] == "0.004"
    assert values["servo_time_constant"] == "0.02" and values["servo_note"] == "n"


def test_an_unmeasurable_judge_warns() -> None:
    measured = dataclasses.replace(
        TrackingJudge(PARAMS.judge_settings()).verdict,
        state="watching",
        reason="needs compensation_in_loop true to measure",
    )
    level, message, _ = report(measured=measured)
    assert level == DiagnosticStatus.WARN and message.endswith(measured.reason)


def _aligner(params: NodeParameters) -> Aligner:
    """The alignment a pipeline with ``params`` makes (its servo part only matters here)."""
    return Aligner(
        use_header=True,
        grid_ns=0,
        wait_ns=0,
        servo=params.servo(),
        servo_window_ns=round(params.servo_window * 1e9),
    )


def test_servo_summary_while_estimating_and_fixed() -> None:
    auto = NodeParameters(servo_model="auto")
    assert servo_summary(_aligner(auto), auto.servo_window) == {
        "state": "estimating",
        "window": auto.servo_window,
    }
    fixed = NodeParameters(servo_model="fixed", servo_time_constant=0.02)
    summary = servo_summary(_aligner(fixed), fixed.servo_window)
    assert summary["state"] == "fixed"
    assert np.isclose(float(summary["time_constant"]), 0.02)  # type: ignore[arg-type]
