"""The guard and the measured tracking over the model in use (genbacklash_ros.node.judges)."""

from __future__ import annotations

import dataclasses

from genbacklash_core import Estimate, GeneralBacklash, Structure
from genbacklash_core.measured import OfflineBaseline
from genbacklash_ros.node.checkpoint import WarmStart, warm_start
from genbacklash_ros.node.compensate import CompensateStage
from genbacklash_ros.node.judges import CompensationJudges, play_of
from genbacklash_ros.node.parameters import NodeParameters


def _judges(params: NodeParameters, **start: object) -> tuple[CompensationJudges, CompensateStage]:
    comp = CompensateStage(params.compensator_options(), compensate=params.compensate)
    fresh: WarmStart = dataclasses.replace(warm_start(params), **start)  # type: ignore[arg-type]
    return CompensationJudges(params, comp, fresh), comp


def test_a_fresh_start_compensates_as_the_verdicts_say() -> None:
    judges, comp = _judges(NodeParameters())
    assert not judges.await_guard
    assert comp.trust == judges.guard.verdict.trust
    assert comp.share == judges.tracking.verdict.trust


def test_a_checkpoint_with_a_baseline_waits_for_the_guard() -> None:
    prior = Estimate.empty(Structure(3))
    baseline = OfflineBaseline(0.03, 40.0)
    judges, comp = _judges(NodeParameters(), prior=prior, baseline=baseline)
    assert judges.await_guard and comp.share == 0.0
    judges.apply()  # no samples judged yet: still waiting
    assert judges.await_guard and comp.share == 0.0
    # without a guard there is nothing to wait for
    judges.configure(NodeParameters(compensation_guard=False))
    assert not judges.await_guard
    assert comp.share == judges.tracking.verdict.trust
    unguarded, comp = _judges(
        NodeParameters(compensation_guard=False), prior=prior, baseline=baseline
    )
    assert not unguarded.await_guard


def test_play_of_a_model() -> None:
    assert play_of(GeneralBacklash([1.0], 0.02, [1.0], 0.03)) == 0.05
    assert play_of(None) is None and play_of("not a model") is None
