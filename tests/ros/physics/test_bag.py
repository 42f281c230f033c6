"""``genbacklash simulate --physics``: the bag round-trips with its truth; bad arguments end
in one line and exit 2."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import genbacklash_ros.physics.bag as physics_bag
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.bagio import BagReader, read_aligned, read_custom_data
from genbacklash_ros.bags.simbags import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    JOINT,
    MOTOR_TOPIC,
    SimulatedBag,
    read_truth,
)
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, main
from genbacklash_ros.node.messages import Float64MultiArray, JointState
from genbacklash_ros.physics import MISSING, physics_record, variant, write_physics_bag

try:
    import mujoco  # noqa: F401

    HAVE_MUJOCO = True
except ImportError:
    HAVE_MUJOCO = False
needs_mujoco = pytest.mark.skipif(not HAVE_MUJOCO, reason="needs mujoco (genbacklash[physics])")


@needs_mujoco
def test_the_bag_round_trips_with_its_truth(tmp_path: Path) -> None:
    p = variant("compliant", bandwidth=30.0)
    cfg = OperationSettings(duration=1.5, travel=(-0.4, 0.4))  # a short sweep for the truth
    made = write_physics_bag(tmp_path / "bag", p, cfg, seed=7, motor_encoder=True)
    rec = physics_record(p, cfg, seed=7)
    with BagReader(tmp_path / "bag") as reader:
        items = list(reader.messages([COMMAND_TOPIC, ENCODER_TOPIC, MOTOR_TOPIC]))
    by_topic = {t: [m.message for m in items if m.topic == t] for t in made.counts}
    assert {t: len(v) for t, v in by_topic.items()} == {t: n for t, (_, n) in made.counts.items()}
    assert all(isinstance(m, Float64MultiArray) for m in by_topic[COMMAND_TOPIC])
    assert all(isinstance(m, JointState) for m in by_topic[ENCODER_TOPIC])
    enc = [m.position[0] for m in by_topic[ENCODER_TOPIC]]  # type: ignore[attr-defined]
    assert np.array_equal(enc, rec.encoder_y)
    mot = [m.position[0] for m in by_topic[MOTOR_TOPIC]]  # type: ignore[attr-defined]
    assert np.array_equal(mot, rec.motor_y[rec.motor_received])
    # the project's reader pairs each reading with the held command
    series = read_aligned(tmp_path / "bag", COMMAND_TOPIC, ENCODER_TOPIC, joint=JOINT)
    assert np.array_equal(series.y, rec.encoder_y)
    assert np.array_equal(series.u, rec.u_all[rec.received])
    truth = read_truth(read_custom_data(tmp_path / "bag"))
    assert truth is not None and truth.scenario == "physics:compliant:operation"
    assert truth.seed == 7 and truth.model == made.truth
    physics = truth.settings["physics"]
    assert physics["geometric_play"] == p.play and physics["parameters"]["bandwidth"] == 30.0
    assert physics["motor_encoder"] is True
    qs = physics["quasi_static"]
    assert qs["geometric"]["c_left"] == p.c_left
    assert qs["command"]["c_right"] == pytest.approx(truth.model.c_right, abs=1e-9)
    assert truth.model.c_left + truth.model.c_right == pytest.approx(p.play, rel=0.05)
    assert np.allclose(truth.c_left, truth.model.c_left, rtol=0.0, atol=1e-9)  # rounded


@needs_mujoco
def test_simulate_physics_writes_the_operation_topics(tmp_path: Path) -> None:
    bag = tmp_path / "bag"
    args = ["simulate", "--physics", "gravity", "--bag", str(bag), "--duration", "1"]
    assert main([*args, "--seed", "3", "--bandwidth", "45"]) == EXIT_OK
    with BagReader(bag) as reader:
        topics = set(reader.topics)
    assert topics == {COMMAND_TOPIC, ENCODER_TOPIC}  # no motor encoder unless asked
    truth = read_truth(read_custom_data(bag))
    assert truth is not None and truth.settings["physics"]["parameters"]["bandwidth"] == 45.0


BAD = [
    (["--physics", "nope"], "invalid choice"),
    (["--physics", "near_ideal"], "give --bag DIR"),
    (["--physics", "near_ideal", "--bag", "B", "--bandwidth", "nan"], "--bandwidth must lie"),
    (["--physics", "near_ideal", "--bag", "B", "--bandwidth", "1e9"], "--bandwidth must lie"),
    (["--physics", "near_ideal", "--bag", "B", "--bandwidth", "x"], "invalid float value"),
    (["--physics", "near_ideal", "--bag", "B", "--duration", "0"], "--duration must lie"),
    (["--physics", "near_ideal", "--bag", "B", "--duration", "inf"], "--duration must lie"),
    (["--physics", "near_ideal", "--bag", "B", "--loss", "2"], "--loss must lie"),
    (["--physics", "near_ideal", "--bag", "B", "--noise", "-1"], "--noise must be"),
    (["--physics", "near_ideal", "--bag", "B", "--wear", "0.1"], "does not take --wear"),
    (["--physics", "near_ideal", "--bag", "B", "--example", "1"], "does not take --example"),
    (["--physics", "coasting", "--bag", "B", "--scenario", "operation"], "--scenario"),
    (["--physics", "coasting", "--bag", "B", "--phases", "op:1"], "bad --phases"),
    (["--scenario", "operation", "--bag", "B", "--bandwidth", "20"], "apply to --physics"),
    (["--example", "1", "-o", "x.csv", "--motor-encoder"], "apply to --physics"),
]


@pytest.mark.parametrize(("args", "match"), BAD)
def test_bad_arguments_end_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], match: str
) -> None:
    args = [str(tmp_path / a) if a in ("B", "x.csv") else a for a in args]
    try:
        code = main(["simulate", *args])
    except SystemExit as exit_:  # argparse's own errors
        code = int(exit_.code or 0)
    assert code == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    errors = [line for line in err.splitlines() if "error:" in line]
    assert len(errors) == 1 and match in errors[0], err
    assert "Traceback" not in err
    assert not (tmp_path / "B").exists()


def _no_bag(*args: object, **kwargs: object) -> SimulatedBag:
    raise AssertionError("valid arguments are not part of this fuzz")


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    words=st.lists(
        st.sampled_from(
            [
                "--physics",
                "near_ideal",
                "gravity",
                "--bandwidth",
                "--duration",
                "--loss",
                "--seed",
                "--motor-encoder",
                "--wear",
                "-1",
                "0",
                "nan",
                "1e400",
                "abc",
                "--",
            ]
        ),
        max_size=8,
    )
)
def test_fuzzed_arguments_never_trace_back(
    words: list[str], capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(physics_bag, "write_physics_bag", _no_bag)
    try:
        code = main(["simulate", "--bag", "/nonexistent/never-written", *words])
    except SystemExit as exit_:
        code = int(exit_.code or 0)
    except AssertionError:
        return  # the arguments were valid: the bag writer was reached
    err = capsys.readouterr().err
    assert code == EXIT_BAD_INPUT, (words, err)
    assert "Traceback" not in err
    assert len([line for line in err.splitlines() if "error:" in line]) == 1


def test_without_mujoco_one_line_says_how_to_install(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setitem(sys.modules, "mujoco", None)  # `import mujoco` raises ImportError
    code = main(["simulate", "--physics", "coasting", "--bag", str(tmp_path / "b")])
    assert code == EXIT_BAD_INPUT
    assert capsys.readouterr().err == f"genbacklash simulate: error: {MISSING}\n"
    assert "pip install 'genbacklash[physics]'" in MISSING
