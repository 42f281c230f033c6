"""``diagnose`` on the MuJoCo drivetrains (issue 23, deliverable 4): known answers per variant.

Short records of the operation scenario (a few seconds: moves, dwells, jogs; 100 Hz held
commands, a 1 kHz load encoder with 2 % loss, a break after each lost reading), diagnosed
with the effects that imitate each other here (the three physical ones, the servo's dead time
and lag before the play, a lag after it) and ``max_steps=1``: the first name is the target's
(``bench/physics_diagnose.py`` runs the whole catalog on 30 s records). The first name must be
the variant's dominant effect. On the near-ideal drivetrain the servo before the gear is
what the ideal backlash misses: it must be named as a lag (before the play, ``input_lag`` /
``time_delay``, or after it, ``linear_dynamics``, whose free run fits these records as well or
better: see BENCHMARKS.md), never as a physical effect; with its motor encoder as the input
nothing physical may be named.
"""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core.diagnose import DiagnoseSettings, diagnose
from genbacklash_core.diagnose.effects import CATALOG
from genbacklash_core.diagnose.physics import PHYSICS_NAMES
from genbacklash_core.scenarios import OperationSettings

try:
    import mujoco  # noqa: F401

    HAVE_MUJOCO = True
except ImportError:
    HAVE_MUJOCO = False

pytestmark = pytest.mark.skipif(not HAVE_MUJOCO, reason="needs mujoco (genbacklash[physics])")

SECONDS = 4.0
RIVALS = tuple(
    effect
    for effect in CATALOG
    if effect.name in (*PHYSICS_NAMES, "time_delay", "input_lag", "linear_dynamics")
)
# compliant is not here: on records this short (4-10 s, seeds 0-2, 60 and 100 Hz) the servo's
# lag or a coasting load is named before the coupling; on the 30 s records of the benchmark
# the coupling is named first (BENCHMARKS.md)
DOMINANT = {
    "coasting": ("coasting_load",),
    "gravity": ("load_torque",),
}


def _samples(
    name: str, seed: int, *, motor: bool = False, bandwidth: float = 60.0, seconds: float = SECONDS
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, y, breaks)`` as the node sees them: the held command (or the motor encoder) at
    each load reading that arrives, a break after each lost one."""
    from genbacklash_ros.physics import physics_record, variant

    rec = physics_record(
        variant(name, bandwidth=bandwidth), OperationSettings(duration=seconds), seed
    )
    keep = rec.received & rec.motor_received if motor else rec.received
    index = np.flatnonzero(keep)
    u = (rec.motor_y if motor else rec.u_all)[index]
    breaks = np.diff(index, prepend=index[0] - 1) > 1
    return u, rec.y_all[index], breaks


@pytest.mark.parametrize("name", list(DOMINANT))
def test_the_dominant_effect_is_named_first(name: str) -> None:
    u, y, breaks = _samples(name, 0)
    result = diagnose(u, y, breaks=breaks, catalog=RIVALS, settings=DiagnoseSettings(max_steps=1))
    assert result.steps, result.summary()
    assert result.effects[0] in DOMINANT[name], result.summary()
    first = result.steps[0]
    assert first.gap_after < first.gap_before
    assert "%" in first.evidence  # the evidence carries its numbers


def test_the_servo_is_named_as_a_lag_not_a_physical_effect() -> None:
    u, y, breaks = _samples("near_ideal", 0)
    result = diagnose(u, y, breaks=breaks, catalog=RIVALS, settings=DiagnoseSettings(max_steps=1))
    assert result.effects, result.summary()
    assert result.effects[0] in ("input_lag", "time_delay", "linear_dynamics"), result.summary()
    assert result.model.physics is None


def test_nothing_physical_is_named_with_the_motor_encoder_as_input() -> None:
    u, y, breaks = _samples("near_ideal", 0, motor=True)
    result = diagnose(u, y, breaks=breaks, catalog=RIVALS, settings=DiagnoseSettings(max_steps=1))
    assert not set(result.effects) & set(PHYSICS_NAMES), result.summary()


def test_a_load_behind_a_slow_servo_is_named_before_the_servo() -> None:
    """The benchmark's coasting record at 20 Hz (seed 0, 30 s, the whole catalog): the path
    "servo lag, then the coasting load" ends a little lower (validation misfit 0.0069) than
    the coasting load fitted behind the lag in one step (0.0076), but its first step closes
    0.0584 -> 0.0459 and its second the rest: the coasting load dominates and is named first,
    not the lag (it was, from the afternoon's path rule until this test)."""
    u, y, breaks = _samples("coasting", 0, bandwidth=20.0, seconds=30.0)
    result = diagnose(u, y, breaks=breaks, settings=DiagnoseSettings(max_steps=1))
    assert result.effects == ("coasting_load",), result.summary()
    assert result.model.input_lag > 0.0  # the servo's lag is in the step
