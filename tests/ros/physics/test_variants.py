"""The physics drivetrains' parameters: the variants, their validation, the servo tuning."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.physics.variants import VARIANTS, DrivetrainParameters, variant


@pytest.mark.parametrize("name", list(VARIANTS))
def test_every_variant_states_its_play_and_servo(name: str) -> None:
    p = variant(name, bandwidth=40.0)
    assert p.name == name and p.bandwidth == 40.0
    assert math.isclose(p.c_left + p.c_right, p.play)
    assert math.isclose(p.play, math.radians(4.0))
    kp, kv = p.servo_gains()
    omega = 2.0 * math.pi * 40.0 / 0.6436
    assert math.isclose(kp, p.engaged_inertia * omega**2)
    assert math.isclose(kv, 2.0 * p.engaged_inertia * omega)  # critically damped
    stored = json.loads(json.dumps(p.to_dict()))
    assert stored["servo_kp"] == kp and stored["play"] == p.play


def test_the_variants_differ_where_their_names_say() -> None:
    near, coast, compliant, gravity = (VARIANTS[n] for n in VARIANTS)
    assert coast.load_friction / coast.load_inertia < 0.05 * near.load_friction / near.load_inertia
    assert near.rigid and coast.rigid and gravity.rigid and not compliant.rigid
    assert gravity.gravity_torque > gravity.load_friction > 0.0
    assert all(VARIANTS[n].gravity_torque == 0.0 for n in ("near_ideal", "coasting", "compliant"))


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"play": -0.01}, "play must be > 0"),
        ({"load_inertia": float("nan")}, "load_inertia must be a finite number"),
        ({"load_friction": -1.0}, "load_friction must be >= 0"),
        ({"bandwidth": 1000.0}, "bandwidth must lie in"),
        ({"slot_offset": 0.05}, "slot_offset"),
        ({"gravity_torque": 5.0}, "below the centre of mass"),
        ({"play": 1.2}, "too wide"),
    ],
)
def test_bad_parameters_are_refused(change: dict[str, float], match: str) -> None:
    with pytest.raises(GenBacklashError, match=match):
        dataclasses.replace(VARIANTS["near_ideal"], **change)


def test_unknown_variant() -> None:
    with pytest.raises(GenBacklashError, match="unknown physics variant 'x'; choose from"):
        variant("x")
    assert isinstance(variant("gravity"), DrivetrainParameters)
