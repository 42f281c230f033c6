"""The guard and the measured tracking over the model in use (genbacklash_ros.node.judges)."""

from __future__ import annotations

import dataclasses

import numpy as np

from genbacklash_core import Estimate, GeneralBacklash, Structure, compensate, simulate_backlash
from genbacklash_core.guard import GuardVerdict
from genbacklash_core.measured import OfflineBaseline
from genbacklash_ros.node.checkpoint import WarmStart, warm_start
from genbacklash_ros.node.compensate import CompensateStage
from genbacklash_ros.node.judges import CompensationJudges, play_of, stricter
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


def _servo_samples() -> tuple[np.ndarray, np.ndarray, np.ndarray, GeneralBacklash]:
    """A load that is where the command is, and a "servo output" that, through the play,
    explains it: the servo model took up all the play (the model describes the servo
    output exactly; on the commands its play is all error)."""
    model = GeneralBacklash.ideal(1.0, 0.05, 0.05)
    commands = 0.3 * np.sin(np.linspace(0.0, 40.0, 4000))
    noise = np.random.default_rng(23).normal(0.0, 1e-3, commands.size)
    servo = compensate(model, commands)
    loads = simulate_backlash(model, servo) + noise
    return servo, loads, commands, model


def test_with_a_servo_modelled_the_stricter_yardstick_counts() -> None:
    servo, loads, commands, model = _servo_samples()
    none = np.zeros(servo.size, dtype=bool)
    judges, comp = _judges(NodeParameters(servo_model="auto"))
    judges.judge_samples(servo, loads, none, model, commands, none)
    assert judges.guard.verdict.state == "on"  # the model describes the servo output
    assert judges.command_guard.verdict.state == "off"  # not the load against the command
    verdict = judges.verdict
    assert verdict.state == "off" and comp.trust == 0.0
    assert verdict.reason.startswith("on the commands: ")
    # without commands (servo_model none) the guard's verdict alone counts
    alone, comp = _judges(NodeParameters())
    alone.judge_samples(servo, loads, none, model)
    assert alone.verdict is alone.guard.verdict and comp.trust == 1.0


def test_stricter_takes_the_lower_trust() -> None:
    on = GuardVerdict(1.0, "on", 0.2, 1.0, 5.0, 10, "compensation on")
    faded = GuardVerdict(0.5, "faded", 0.85, 1.0, 1.2, 10, "compensation faded")
    judging = GuardVerdict(1.0, "judging", float("nan"), float("nan"), float("nan"), 0, "")
    assert stricter(on, faded).trust == 0.5 and stricter(faded, on) is faded
    assert stricter(on, judging) is on
