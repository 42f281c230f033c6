"""``--motor-encoder TOPIC [--motor-joint NAME]`` on replay, identify, diagnose and readings:
the help says it, a bad selection ends in one line and exit 2 (naming the bag's topics), and
``readings`` writes a ``motor`` column that identify takes as the bag's rows."""

from __future__ import annotations

from pathlib import Path

import pytest

from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, JOINT, MOTOR_TOPIC
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, main

try:
    import mujoco  # noqa: F401

    HAVE_MUJOCO = True
except ImportError:
    HAVE_MUJOCO = False
needs_mujoco = pytest.mark.skipif(not HAVE_MUJOCO, reason="needs mujoco (genbacklash[physics])")

TOPICS = ["--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC, "--joint", JOINT]


@pytest.fixture(scope="module")
def bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    pytest.importorskip("mujoco", reason="needs mujoco (genbacklash[physics])")
    from genbacklash_ros.physics import variant, write_physics_bag

    path = tmp_path_factory.mktemp("motor_cli") / "bag"
    cfg = OperationSettings(duration=3.0, travel=(-0.4, 0.4))
    write_physics_bag(path, variant("near_ideal"), cfg, seed=2, motor_encoder=True)
    return path


@pytest.mark.parametrize("command", ["replay", "identify", "diagnose", "readings"])
def test_the_help_names_the_motor_options(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as done:
        main([command, "--help"])
    assert done.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    assert "--motor-encoder TOPIC" in out and "--motor-joint NAME" in out


def _one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@needs_mujoco
@pytest.mark.parametrize("command", ["identify", "diagnose", "readings", "replay"])
def test_a_missing_motor_topic_names_the_bags_topics(
    command: str, bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    extra = ["-o", str(tmp_path / "out")] if command in ("replay", "readings") else []
    if command == "readings":
        extra = ["-o", str(tmp_path / "r.csv")]
    code = main([command, str(bag), *TOPICS, "--motor-encoder", "/motr", *extra])
    assert code == EXIT_BAD_INPUT
    line = _one_line_error(capsys)
    assert "motor encoder: topic '/motr' is not in" in line
    assert f"{MOTOR_TOPIC} (sensor_msgs/msg/JointState" in line


@needs_mujoco
@pytest.mark.parametrize(
    ("args", "reason"),
    [
        (["--motor-encoder", ENCODER_TOPIC], "must differ from the command and encoder"),
        (["--motor-encoder", COMMAND_TOPIC], "must differ from the command and encoder"),
        (["--motor-encoder", MOTOR_TOPIC, "--motor-joint", "rotor"], "joint 'rotor' is not in"),
        (["--motor-joint", JOINT], "--motor-joint needs --motor-encoder TOPIC"),
        (["--param", "gear_input=motor_encoder"], "name the motor encoder's topic with"),
    ],
)
def test_a_bad_motor_selection_is_one_line(
    args: list[str], reason: str, bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["identify", str(bag), *TOPICS, *args]) == EXIT_BAD_INPUT
    assert reason in _one_line_error(capsys)


@needs_mujoco
def test_replay_refuses_a_motor_input_without_its_topic(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    code = main(
        ["replay", str(bag), *TOPICS, "-o", str(out), "--param", "gear_input=motor_encoder"]
    )
    assert code == EXIT_BAD_INPUT
    assert "--motor-encoder TOPIC" in _one_line_error(capsys)
    assert not out.exists()


def test_a_csv_takes_no_motor_topic(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv = tmp_path / "d.csv"
    csv.write_text("u,y\n0,0\n1,1\n")
    assert main(["identify", str(csv), "--motor-encoder", MOTOR_TOPIC]) == EXIT_BAD_INPUT
    assert "name its motor column 'motor'" in _one_line_error(capsys)


@needs_mujoco
def test_readings_writes_a_motor_column_identify_reads_as_the_bag(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv = tmp_path / "r.csv"
    motor = ["--motor-encoder", MOTOR_TOPIC]
    assert main(["readings", str(bag), *TOPICS, *motor, "-o", str(csv)]) == EXIT_OK
    assert "checked: identify and diagnose take the same rows" in capsys.readouterr().err
    assert csv.read_text().splitlines()[0] == "t,motor,y"
    assert main(["identify", str(csv), "--json"]) == EXIT_OK
    from_csv = capsys.readouterr().out
    assert main(["identify", str(bag), *TOPICS, *motor, "--json"]) == EXIT_OK
    assert capsys.readouterr().out == from_csv
