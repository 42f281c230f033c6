"""What each drivetrain does in motion: coasting, ringing, a held flank; the operation
scenario's clocks on the physics."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the physics drivetrains need mujoco (genbacklash[physics])")

from genbacklash_core.scenarios import OperationSettings, operation_record
from genbacklash_ros.physics.engine import Drivetrain, Trajectory
from genbacklash_ros.physics.record import physics_record
from genbacklash_ros.physics.variants import variant


def _move_and_stop(name: str, speed: float = 1.5) -> tuple[Trajectory, int]:
    """A ramp at ``speed`` for 0.15 s (commands at every step), then held for 0.3 s; and
    the first row where the motor has stopped (within 0.2 mrad of where it ends)."""
    sim = Drivetrain(variant(name))
    dt = sim.step_ns / 1e9
    ramp = speed * dt * np.arange(1, round(0.15 / dt) + 1)
    run = sim.advance(np.concatenate([ramp, np.full(round(0.3 / dt), ramp[-1])]))
    return run, int(np.argmax(np.abs(run.motor - run.motor[-1]) < 2e-4))


def test_coasting_load_moves_on_after_the_motor_stops() -> None:
    coast, stop = _move_and_stop("coasting")
    after = np.ptp(coast.load[stop:])
    assert after > 0.3 * variant("coasting").play  # it coasts into the play
    near, stop = _move_and_stop("near_ideal")
    assert np.ptp(near.load[stop:]) < 1e-3  # friction stops it with the motor


def test_compliant_coupling_rings_at_engagement() -> None:
    run, _ = _move_and_stop("compliant")
    p = variant("compliant")
    deflection = run.load - run.slot  # the spring's wind-up
    k = np.searchsorted(run.t_ns, 50_000_000)  # engaged and moving from ~25 ms on
    swing = deflection[k:] - np.mean(deflection[k:])
    crossings = np.count_nonzero(np.diff(np.sign(swing)) != 0)
    # ~22 Hz for 0.4 s: some 17 periods; at least a few full swings
    assert crossings >= 8
    assert np.ptp(deflection[k:]) > 2 * p.load_friction / p.coupling_stiffness
    rigid, _ = _move_and_stop("near_ideal")
    assert np.array_equal(rigid.load, rigid.slot)


def test_gravity_holds_the_load_on_one_flank_going_down() -> None:
    p = variant("gravity")
    sim = Drivetrain(p, position=0.2)
    dt = sim.step_ns / 1e9
    down = sim.advance(0.2 - 0.5 * dt * np.arange(1, round(0.8 / dt)))  # 0.2 -> -0.2 rad
    pin = down.motor - down.slot - p.slot_offset
    settled = pin[len(pin) // 4 :]
    # the pin stays on the upward branch's flank (+play/2) although the motor goes down
    assert np.all(settled > p.play / 2 - 0.05 * p.play)
    sim = Drivetrain(variant("near_ideal"), position=0.2)
    down = sim.advance(0.2 - 0.5 * dt * np.arange(1, round(0.8 / dt)))
    pin = down.motor - down.slot - p.slot_offset
    assert np.all(pin[len(pin) // 4 :] < -p.play / 2 + 0.05 * p.play)  # the other flank


def test_the_record_has_the_operation_scenarios_clocks_and_encoder() -> None:
    cfg = OperationSettings(duration=2.0)
    rec = physics_record(variant("near_ideal"), cfg, seed=4)
    op = operation_record(cfg, seed=4)
    for field in ("command_t_ns", "command_u", "sample_t_ns", "received", "u_all"):
        assert np.array_equal(getattr(rec, field), getattr(op, field)), field
    quantum = cfg.quantum
    assert np.allclose(np.round(rec.y_all / quantum) * quantum, rec.y_all)
    assert np.max(np.abs(rec.y_all - rec.x_all)) <= quantum / 2 + 1e-12
    assert 0.9 < rec.motor_received.mean() < 1.0
    assert not np.array_equal(rec.motor_received, rec.received)  # losses of its own
    # the load is the physics': within the play of the motor, not the play operator
    assert np.all(np.abs(rec.motor_all - rec.x_all) < variant("near_ideal").play)
    assert np.max(np.abs(rec.x_all - op.x_all)) > 1e-3


def test_records_are_reproducible() -> None:
    cfg = OperationSettings(duration=0.5)
    a = physics_record(variant("coasting"), cfg, seed=2)
    b = physics_record(variant("coasting"), cfg, seed=2)
    assert np.array_equal(a.y_all, b.y_all) and np.array_equal(a.motor_y, b.motor_y)
    c = physics_record(variant("coasting"), cfg, seed=3)
    assert not np.array_equal(a.command_u, c.command_u)
    with pytest.raises(ValueError, match="OperationSettings"):
        physics_record(variant("coasting"), object(), seed=2)  # type: ignore[arg-type]
