"""``identify``'s standard deviations on a physics record hold the quasi-static play (issue 22).

A short MuJoCo record (10 s of the operation scenario, 60 Hz servo) of two drivetrains: the
near-ideal one, whose batch estimate sits ~1 mrad beside the quasi-static play (the servo's
lag), and the gravity one, ~30 mrad beside it (gravity holds the load on one flank). The
statistical standard deviation (white residuals) is 30-40 times too small on both; the
reported ``play_std``, statistical and model error together, holds the truth at 2 sigma.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.bagio import BagReader
from genbacklash_ros.bags.simbags import read_truth
from genbacklash_ros.cli.main import main

pytest.importorskip("mujoco", reason="needs mujoco (genbacklash[physics])")

TOPICS = ["--command", "/command", "--encoder", "/encoder", "--joint", "drive_joint"]


@pytest.mark.parametrize("name", ["near_ideal", "gravity"])
def test_two_sigma_holds_the_quasi_static_play(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str
) -> None:
    from genbacklash_ros.physics import variant, write_physics_bag

    bag = tmp_path / "bag"
    write_physics_bag(bag, variant(name, bandwidth=60.0), OperationSettings(duration=10.0), 0)
    with BagReader(bag) as reader:
        truth = read_truth(reader.custom_data)
    assert truth is not None
    true_play = float(truth.c_left[0] + truth.c_right[0])
    assert main(["identify", str(bag), *TOPICS, "--json"]) in (0, 3)
    out = json.loads(capsys.readouterr().out)
    error = abs(out["play"] - true_play)
    assert error > 2.0 * out["play_std_statistical"]  # the noise alone does not explain it
    assert error <= 2.0 * out["play_std"], (error, out["play_std"])
    assert out["model_error_dominates"] is True
    assert out["play_std"] == pytest.approx(
        (out["play_std_statistical"] ** 2 + out["play_std_model"] ** 2) ** 0.5
    )
    if name == "near_ideal":  # a band, not everything, where the play operator nearly holds
        assert 2.0 * out["play_std"] < 0.5 * true_play
    # gravity: the fit restarts at the holds the readings falsify (restart_holds), and the
    # band is the plain free run's misfit, which that fit does not minimise: on this 10 s
    # record 2 sigma is about twice the play, and the text says the band is wider than the
    # play (the restarted free run's own residual gave 1.6 mrad for an 11 mrad error: no band)
    for key, std in out["parameter_std"].items():
        assert std >= out["parameter_std_statistical"][key]


def test_the_text_says_when_the_model_error_dominates(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from genbacklash_ros.physics import variant, write_physics_bag

    bag = tmp_path / "bag"
    write_physics_bag(bag, variant("gravity"), OperationSettings(duration=6.0), 1)
    assert main(["identify", str(bag), *TOPICS]) in (0, 3)
    text = capsys.readouterr().out
    assert "of which (2 sigma) statistical +/-" in text
    assert "the model error dominates" in text
