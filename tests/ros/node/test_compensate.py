"""CompensateStage.status: the state of compensation and, for the diagnostics, why."""

from __future__ import annotations

import math

from genbacklash_core import CompensatorOptions, GeneralBacklash, GuardVerdict
from genbacklash_core.measured import TrackingVerdict
from genbacklash_ros.node.compensate import CompensateStage
from tests.ros.node.test_health import _converged as converged

GUARD_JUDGING = GuardVerdict(1.0, "judging", math.nan, math.nan, math.nan, 0, "guard judging")


def _measured(trust: float, state: str, reason: str) -> TrackingVerdict:
    return TrackingVerdict(trust, state, math.nan, math.nan, math.nan, 1.0, 1.0, reason)


def test_a_trial_at_part_weight_says_so() -> None:
    """A trial (the measured-tracking judge still judging, at part weight) fades
    compensation; the reason is the judge's, not a bare "compensation faded"."""
    stage = CompensateStage(CompensatorOptions(), compensate=True)
    est = converged(GeneralBacklash((1.0,), 0.05, (1.0,), 0.05))
    trial = "compensation on trial at 20 % while its tracking is measured"
    stage.share = 0.2
    status = stage.status(est, (), GUARD_JUDGING, _measured(0.2, "judging", trial))
    assert status.state == "faded"
    assert trial in status.reason
    # at full weight while judging, nothing to explain beyond the state
    stage.share = 1.0
    full = stage.status(est, (), GUARD_JUDGING, _measured(1.0, "judging", "at full weight"))
    assert (full.state, full.reason) == ("on", "compensation on")
    held = stage.status(est, (), GUARD_JUDGING, _measured(0.0, "judging", "held off (1.0 of 3 s)"))
    assert held.reason == "held off (1.0 of 3 s)"
