"""The replay report checks its plant before it leads with predicted cuts (issue 23).

A report used to lead with "final estimate's inverse: 93 % cut" on a drivetrain where
compensating makes tracking worse, because the plant it simulates (the bag's stored play,
or the final estimate) does not describe the recording. The plant is now run free on the
recorded commands and judged by the node's guard thresholds.
"""

from __future__ import annotations

import dataclasses
import html
import math
import re
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import GeneralBacklash, simulate_backlash
from genbacklash_core.guard import GuardSettings
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.replay import replay
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, JOINT, write_operation_bag
from genbacklash_ros.reports.plant_check import check_plant
from genbacklash_ros.reports.replay import tracking_errors, write_report

try:
    import mujoco  # noqa: F401

    HAVE_MUJOCO = True
except ImportError:
    HAVE_MUJOCO = False
needs_mujoco = pytest.mark.skipif(not HAVE_MUJOCO, reason="needs mujoco (genbacklash[physics])")

TOPICS = {"command_topic": "/command", "encoder_topic": "/encoder", "joint": "drive_joint"}


def _text(page: str) -> str:
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", page)).split())


def test_the_ratio_is_the_plants_miss_over_the_commands_miss() -> None:
    model = GeneralBacklash.ideal(1.0, 0.05, 0.05)
    u = 0.5 * np.sin(np.linspace(0.0, 12.0, 600))
    y = simulate_backlash(model, u, 0.0) + np.random.default_rng(3).normal(0.0, 1e-3, u.size)
    good = check_plant(model, u, y, GuardSettings(), "truth")
    assert good.describes and good.ratio < 0.1
    assert "compensates in full" in good.sentence()
    assert good.no_model_rms == pytest.approx(float(np.sqrt(np.mean((y - u) ** 2))))
    wide = GeneralBacklash.ideal(1.0, 0.2, 0.2)  # four times the play
    bad = check_plant(wide, u, y, GuardSettings(), "estimate")
    assert not bad.describes
    assert bad.ratio == pytest.approx(bad.model_rms / bad.no_model_rms)
    assert "final estimate" in bad.sentence() and f"ratio {bad.ratio:.2f}" in bad.sentence()
    assert "turns compensation off" in bad.sentence()
    # the guard's own thresholds judge it: a stricter guard rejects what the default takes
    middling = GeneralBacklash.ideal(1.0, 0.07, 0.07)
    ratio = check_plant(middling, u, y, GuardSettings(), "estimate").ratio
    assert 0.0 < ratio < 0.75
    strict = GuardSettings(rho_full=ratio / 2, rho_off=ratio * 1.5)
    faded = check_plant(middling, u, y, strict, "estimate")
    assert not faded.describes and "fades compensation" in faded.sentence()


def test_readings_equal_to_the_commands_leave_nothing_to_judge() -> None:
    u = np.linspace(0.0, 1.0, 50)
    check = check_plant(GeneralBacklash.ideal(1.0, 0.1, 0.1), u, u.copy(), GuardSettings(), "x")
    assert math.isnan(check.ratio) and check.describes


def test_a_drivetrain_the_play_describes_keeps_its_headline(tmp_path: Path) -> None:
    bag = tmp_path / "op"
    write_operation_bag(bag, OperationSettings(duration=8.0), seed=2)
    result = replay(
        bag, tmp_path / "o", command_topic=COMMAND_TOPIC, encoder_topic=ENCODER_TOPIC, joint=JOINT
    )
    errors = tracking_errors(result)
    assert errors is not None and errors.check is not None
    assert errors.trusted and errors.check.ratio < 0.3
    text = _text(write_report(result, tmp_path / "rep").read_text())
    assert "Not a prediction" not in text and "does not describe the recording" not in text
    assert "RMS tracking error without compensation" in text


@needs_mujoco
def test_a_compliant_coupling_is_not_reported_as_a_93_percent_cut(tmp_path: Path) -> None:
    """The issue's case: a spring after the play, where even a compensator given the true
    play makes tracking worse (BENCHMARKS.md, physics drivetrains)."""
    from genbacklash_ros.physics import variant, write_physics_bag

    bag = tmp_path / "compliant"
    write_physics_bag(bag, variant("compliant", bandwidth=60), OperationSettings(duration=10.0), 3)
    result = replay(bag, tmp_path / "o", **TOPICS)  # type: ignore[arg-type]
    errors = tracking_errors(result)
    assert errors is not None and errors.check is not None and errors.plant == "truth"
    assert not errors.trusted, errors.check
    text = _text(write_report(result, tmp_path / "rep").read_text())
    assert "come from a plant that does not describe the recording" in text  # the alert
    summary = text[text.index("Tracking error") :]
    assert summary.startswith("Tracking error Not a prediction for this drivetrain")
    assert "Measured while recording" in text
    assert f"ratio {errors.check.ratio:.2f}" in text
    # the issue's own case: no truth in the bag, the final estimate as the plant
    bare = tracking_errors(dataclasses.replace(result, custom_data=None))
    assert bare is not None and bare.plant == "estimate" and bare.check is not None
    assert not bare.trusted, bare.check
