"""The node's pipeline in closed loop with physics drivetrains: compensation never harms."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the physics drivetrains need mujoco (genbacklash[physics])")

from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.cli.main import EXIT_OK, main
from genbacklash_ros.node.checkpoint import load_checkpoint, save_checkpoint
from genbacklash_ros.physics.bag import write_physics_bag
from genbacklash_ros.physics.loop import Clocks, node_loop, open_loop
from genbacklash_ros.physics.variants import variant


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e * e)))


def test_the_measured_tracking_keeps_compensation_on_where_it_helps() -> None:
    params = variant("near_ideal", bandwidth=60.0)
    clocks = Clocks(0, 30.0)
    loads, _est, _guard, measured = node_loop(params, clocks, guard=True, delay_ns=2_000_000)
    none = open_loop(params, clocks, clocks.values, 2_000_000)
    cut = 1.0 - _rms(loads - clocks.desired) / _rms(none - clocks.desired)
    assert measured.state == "on" and measured.ratio < 0.5, measured.reason
    assert cut > 0.4


def test_compensation_on_a_flank_held_by_gravity_never_tracks_worse() -> None:
    # gravity holds one flank over part of the travel: the model's guard let compensation
    # run for a second before it switched it off (before the measured tracking's trial at
    # half weight this record tracked 2.6 % worse than doing nothing). Since the guard's
    # hysteresis: it judges the model off at 7.1 s; the next one reads 0.71 on the samples
    # remembered (it was tried at once before), its successors 0.86-1.13, never 1000 new
    # samples in a row at or below 0.75: nothing is tried and the guard ends off
    params = variant("gravity", bandwidth=60.0)
    clocks = Clocks(1, 40.0)
    loads, _est, guard, _measured = node_loop(params, clocks, guard=True)
    none = open_loop(params, clocks, clocks.values)
    assert guard.state == "off", guard.reason
    assert _rms(loads - clocks.desired) <= 1.02 * _rms(none - clocks.desired)


def test_a_trial_on_a_compliant_coupling_never_tracks_worse() -> None:
    # the motor encoder as the gear's input: the first estimate came 2.6 s in, before the
    # judge held a full baseline, and its trial at half weight put a jump at each reversal
    # that rang the coupling's spring until the model's guard switched it off (2.5 % worse
    # than doing nothing over the record); now the trial waits for the baseline and its
    # weight grows with the evidence on it
    params = variant("compliant", bandwidth=20.0)
    clocks = Clocks(2, 40.0)
    loads, _est, _guard, _measured = node_loop(params, clocks, guard=True, motor=True)
    none = open_loop(params, clocks, clocks.values)
    assert _rms(loads - clocks.desired) <= 1.02 * _rms(none - clocks.desired)


def _offline_start(tmp_path: Path, name: str, bandwidth: float, seed: int, duration: float) -> Path:
    """identify's checkpoint on another record of the drivetrain (no compensation in it)."""
    params = variant(name, bandwidth=bandwidth)
    bag, start = tmp_path / "offline", tmp_path / "start.json"
    write_physics_bag(bag, params, OperationSettings(duration=duration), seed)
    topics = ["--command", "/command", "--encoder", "/encoder", "--joint", "drive_joint"]
    assert main(["identify", str(bag), *topics, "--checkpoint", str(start)]) == EXIT_OK
    return start


def test_a_start_without_an_offline_baseline_measures_it_before_it_compensates(
    tmp_path: Path,
) -> None:
    # a checkpoint that holds no baseline (the node's own, or a record that may have had
    # compensation in it): the judge holds it off for its baseline, then tries it
    params = variant("near_ideal", bandwidth=60.0)
    start = _offline_start(tmp_path, "near_ideal", 60.0, 100, 20.0)
    saved = load_checkpoint(start)
    save_checkpoint(start, dataclasses.replace(saved, baseline=None))
    clocks = Clocks(0, 20.0)
    loads, _est, _guard, measured = node_loop(
        params, clocks, guard=True, extra={"checkpoint_file": str(start)}
    )
    none = open_loop(params, clocks, clocks.values) - clocks.desired
    assert measured.state == "on", measured.reason
    assert 3.0 <= measured.off_time < 3.5  # the baseline (judged at each feed), then no more
    early = clocks.t < 2_500_000_000  # held off: the load moves as without compensation
    assert np.allclose(loads[early] - clocks.desired[early], none[early])
    assert _rms(loads - clocks.desired) < 0.5 * _rms(none)


def test_a_start_with_the_offline_records_baseline_compensates_early(tmp_path: Path) -> None:
    # identify measured the record's tracking without compensation into the checkpoint: the
    # judge starts from it, compensation waits only for the guard's first verdict on this
    # machine (about 1.7 s here, not the 3 s baseline) and is judged against the offline one
    # once a live probe agrees with it (within OFFLINE_AGREE), else against the live one
    params = variant("near_ideal", bandwidth=60.0)
    start = _offline_start(tmp_path, "near_ideal", 60.0, 100, 20.0)
    assert load_checkpoint(start).baseline is not None
    clocks = Clocks(0, 20.0)
    loads, _est, _guard, measured = node_loop(
        params, clocks, guard=True, extra={"checkpoint_file": str(start)}
    )
    none = open_loop(params, clocks, clocks.values) - clocks.desired
    assert measured.state == "on", measured.reason
    # the live probe agreed: the offline baseline confirmed, measured live for 2.5 s at most
    assert measured.baseline == "offline" and "agrees" in measured.reason, measured.reason
    assert measured.live_time < 2.5
    third = (clocks.t >= 2_500_000_000) & (clocks.t < 3_000_000_000)
    assert _rms(loads[third] - clocks.desired[third]) < 0.7 * _rms(none[third])
    assert _rms(loads - clocks.desired) < 0.4 * _rms(none)


@pytest.mark.parametrize("scale", [2.0, 0.5])
def test_a_wrong_offline_baseline_never_makes_a_coasting_load_track_worse(
    tmp_path: Path, scale: float
) -> None:
    # a load that coasts into the play: compensation with the play makes it track 80 %
    # worse. A trial from the first command at a tenth of its weight, judged on the offline
    # baseline, perturbed it for the rest of the record (-8.9 % over 40 s, seed 1); the start
    # waits for the guard's first verdict, and a wrong baseline (here twice or half the
    # offline record's) is replaced by the live one before any trial
    params = variant("coasting", bandwidth=100.0)
    start = _offline_start(tmp_path, "coasting", 100.0, 101, 20.0)
    saved = load_checkpoint(start)
    assert saved.baseline is not None
    wrong = dataclasses.replace(saved.baseline, rms=scale * saved.baseline.rms)
    save_checkpoint(start, dataclasses.replace(saved, baseline=wrong))
    clocks = Clocks(1, 20.0)
    loads, _est, _guard, _measured = node_loop(
        params, clocks, guard=True, extra={"checkpoint_file": str(start)}
    )
    none = open_loop(params, clocks, clocks.values)
    assert _rms(loads - clocks.desired) <= 1.02 * _rms(none - clocks.desired)


def test_late_stamps_are_stamped_when_a_busy_publisher_is_done() -> None:
    clocks = Clocks(0, 10.0, late_ms=1.5)
    assert np.all(clocks.stamps >= clocks.t) and np.all(np.diff(clocks.stamps) > 0)
    early = np.rint(np.diff(clocks.stamps) / 1e6) <= 0
    assert 0.03 < early.mean() < 0.2  # bunched as the live arm's 500 Hz stamps (7 %)
    plain = Clocks(0, 10.0)
    assert np.array_equal(plain.stamps, plain.t)


@pytest.mark.parametrize("seed", [0, 1])
def test_a_coasting_load_is_not_tried_when_the_readings_come_stamped_late(seed: int) -> None:
    """The live demo's failure in process: readings stamped by a busy publisher (8 % of
    them less than half a period after the one before) broke the sample rule's chain, the
    guard restarted its free run there and let trials through on the coasting drivetrain
    (whose true-play compensator tracks 65-75 % worse). Now the node never sends a command
    other than the desired one there: the loop is the uncompensated run."""
    params = variant("coasting", bandwidth=60.0)
    clocks = Clocks(seed, 40.0, late_ms=1.5)
    loads, _est, guard, _measured = node_loop(params, clocks, guard=True)
    none = open_loop(params, clocks, clocks.values)
    assert guard.state == "off" and guard.ratio > 1.2
    assert np.array_equal(loads, none)


def test_with_the_servo_modelled_a_compliant_coupling_never_tracks_worse() -> None:
    # servo_model=auto: the guard on the modelled servo output, its free run re-anchored at
    # every lost reading, read 0.57-0.79 and passed the model; its compensation rang the
    # coupling, 3.2 % worse than nothing over the record and 8.7 % over the second half. On
    # the commands (lost readings bridged along monotone commands) the model reads 0.9-1.7
    params = variant("compliant", bandwidth=60.0)
    clocks = Clocks(2, 40.0)
    loads, _est, guard, _measured = node_loop(
        params, clocks, guard=True, extra={"servo_model": "auto"}
    )
    none = open_loop(params, clocks, clocks.values) - clocks.desired
    node = loads - clocks.desired
    half = clocks.t >= clocks.t[-1] // 2
    assert _rms(node) <= 1.02 * _rms(none)
    assert _rms(node[half]) <= 1.02 * _rms(none[half]), guard.reason


def test_with_the_servo_modelled_a_near_ideal_drivetrain_is_compensated() -> None:
    # the second yardstick leaves a drivetrain the play operator describes compensated
    params = variant("near_ideal", bandwidth=60.0)
    clocks = Clocks(0, 20.0)
    loads, _est, guard, measured = node_loop(
        params, clocks, guard=True, extra={"servo_model": "auto"}
    )
    none = open_loop(params, clocks, clocks.values)
    assert guard.state == "on" and measured.state == "on", (guard.reason, measured.reason)
    assert _rms(loads - clocks.desired) < 0.6 * _rms(none - clocks.desired)
