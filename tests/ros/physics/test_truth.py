"""The truth: the geometric play against the quasi-static characteristic of a slow sweep."""

from __future__ import annotations

import pytest

pytest.importorskip("mujoco", reason="the physics drivetrains need mujoco (genbacklash[physics])")

from genbacklash_ros.physics.truth import quasi_static
from genbacklash_ros.physics.variants import variant


def test_near_ideal_sweep_finds_the_geometric_play() -> None:
    p = variant("near_ideal")
    q = quasi_static(p, (-0.3, 0.3))
    # against the motor: the contact's penetration only
    assert q.motor_model.c_left == pytest.approx(p.c_left, rel=0.01)
    assert q.motor_model.c_right == pytest.approx(p.c_right, rel=0.01)
    # against the command: plus the servo's static error under the friction, F / kp a side
    kp, _ = p.servo_gains()
    assert q.play == pytest.approx(p.play + 2 * p.load_friction / kp, rel=0.01)
    assert q.play == pytest.approx(p.play, rel=0.03)
    assert q.model.m_left[0] == pytest.approx(1.0, abs=1e-3)
    assert q.model.m_right[0] == pytest.approx(1.0, abs=1e-3)
    assert q.held_share < 0.02 and min(q.samples) > 1000
    assert q.geometric.c_left == p.c_left


def test_compliant_sweep_adds_the_coupling_wind_up() -> None:
    p = variant("compliant")
    q = quasi_static(p, (-0.3, 0.3))
    wind_up = 2 * p.load_friction / p.coupling_stiffness
    assert q.motor_model.c_left + q.motor_model.c_right == pytest.approx(p.play + wind_up, rel=0.01)


def test_gravity_sweep_holds_one_flank_over_part_of_the_travel() -> None:
    q = quasi_static(variant("gravity"), (-1.2, 1.2), speed=0.5)
    # held where m g l cos(q) > friction, |q| < 0.59: about half of the travel
    assert 0.3 < q.held_share < 0.55
    assert q.samples[0] < 0.7 * q.samples[1]  # the down branch seen only outside it
