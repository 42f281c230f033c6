"""The servo modelled with the play on a physics drivetrain (issue 23, deliverable 2).

A near-ideal MuJoCo drivetrain (a PD position servo before a pin in a slot) at 20, 60 and
100 Hz servo bandwidth, 20 s of operation: ``replay`` (the node) and ``identify`` (batch) with
``servo_model=auto`` read the play within 10 % of the geometric one and within 5 % of each
other, and a CSV of the readings gives identify's answer to the last digit. At 20 Hz the
play seen from the command includes the servo's static error under the load's Coulomb
friction (``friction / kp`` a side, 13 % of the play): no servo model of the command can tell
it from play, and the compensator must invert it too. There the estimate is held to the
quasi-static characteristic measured against the command (:mod:`genbacklash_ros.physics.truth`).
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.cli.main import EXIT_NOT_CONVERGED, EXIT_OK, main

try:
    import mujoco  # noqa: F401

    HAVE_MUJOCO = True
except ImportError:
    HAVE_MUJOCO = False

pytestmark = pytest.mark.skipif(not HAVE_MUJOCO, reason="needs mujoco (genbacklash[physics])")

TOPICS = ["--command", "/command", "--encoder", "/encoder", "--joint", "drive_joint"]
AUTO = ["--param", "servo_model=auto"]


def _json(argv: list[str], capsys: pytest.CaptureFixture[str]) -> dict[str, object]:
    code = main(argv)
    out, err = capsys.readouterr()
    assert code in (EXIT_OK, EXIT_NOT_CONVERGED), err
    return dict(json.loads(out))


def _play(result: dict[str, object]) -> float:
    shape = result["model"] if "backlash" not in result else result
    assert isinstance(shape, dict)
    bl = shape["backlash"]
    return float(bl["c_left"]) + float(bl["c_right"])


@pytest.mark.parametrize("bandwidth", [20.0, 60.0, 100.0])
def test_replay_and_identify_read_the_play_through_the_servo(
    bandwidth: float, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    from genbacklash_ros.physics import variant, write_physics_bag
    from genbacklash_ros.physics.truth import quasi_static

    params = variant("near_ideal", bandwidth=bandwidth)
    bag = tmp_path / "bag"
    write_physics_bag(bag, params, OperationSettings(duration=20.0), 0)
    out = str(tmp_path / "out")
    replay = ["replay", str(bag), *TOPICS, "-o", out, "--json", "--no-progress", *AUTO]
    online = _json(replay, capsys)
    batch = _json(["identify", str(bag), *TOPICS, "--json", *AUTO], capsys)
    assert online["servo"]["state"] == "estimated"  # type: ignore[index]
    assert batch["servo"]["estimated"] is True  # type: ignore[index]
    geometric = params.c_left + params.c_right
    if bandwidth >= 60.0:
        truth = geometric
    else:  # the servo's static error under friction is play as the command sees it
        truth = quasi_static(params, OperationSettings().travel).play
        assert truth > 1.1 * geometric
    assert _play(online) == pytest.approx(truth, rel=0.05 if bandwidth < 60 else 0.1)
    assert _play(batch) == pytest.approx(truth, rel=0.05 if bandwidth < 60 else 0.1)
    assert _play(online) == pytest.approx(_play(batch), rel=0.05)
    # a CSV of the same readings: the same answer, servo included
    csv = tmp_path / "readings.csv"
    assert main(["readings", str(bag), *TOPICS, "-o", str(csv)]) == EXIT_OK
    capsys.readouterr()
    from_csv = _json(["identify", str(csv), "--json", *AUTO], capsys)
    assert from_csv == batch
