"""``genbacklash replay``: the pipeline fed from a bag, its output bag, report and errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import paper_example
from genbacklash_ros.bags.bagio import BagReader
from genbacklash_ros.bags.replay import OUTPUT_TOPICS, replay
from genbacklash_ros.bags.simbags import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    JOINT,
    read_truth,
    write_drivetrain_bag,
    write_example_bag,
)
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, main

TOPICS = ["--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC, "--joint", JOINT]


@pytest.fixture(scope="module")
def example_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("bags") / "ex1"
    write_example_bag(bag, 1, seed=1, n_samples=1500)
    return bag


@pytest.fixture(scope="module")
def replayed(example_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    out = tmp_path_factory.mktemp("replay")
    code = main(
        ["replay", str(example_bag), *TOPICS, "-o", str(out / "bag"), "--report", str(out / "rep")]
    )
    assert code == EXIT_OK
    return out / "bag", out / "rep"


def test_replay_reaches_the_known_parameters(example_bag: Path, tmp_path: Path) -> None:
    result = replay(
        example_bag,
        tmp_path / "out",
        command_topic=COMMAND_TOPIC,
        encoder_topic=ENCODER_TOPIC,
        joint=JOINT,
    )
    truth = paper_example(1).model.parameters()
    assert result.error == ""
    assert result.estimate.state.value == "converged"
    assert np.max(np.abs(result.estimate.parameters - truth)) < 0.05
    assert result.stats.compensated == result.stats.commands == 1500
    assert result.messages_in == 3000


def test_output_bag_has_the_node_topics(replayed: tuple[Path, Path]) -> None:
    out, _ = replayed
    with BagReader(out) as reader:
        topics = reader.topics
        assert set(topics) == {COMMAND_TOPIC, ENCODER_TOPIC, *OUTPUT_TOPICS.values()}
        assert topics[OUTPUT_TOPICS["compensated_command"]].count == 1500
        assert topics[OUTPUT_TOPICS["compensated_command"]].msgtype == (
            "std_msgs/msg/Float64MultiArray"
        )
        assert topics[OUTPUT_TOPICS["estimate"]].count > 5
        estimates = list(reader.messages([OUTPUT_TOPICS["estimate"]]))
        diags = list(reader.messages(["/diagnostics"]))
    label = estimates[-1].message.layout.dim[0].label  # type: ignore[union-attr]
    assert label.startswith("m_left_1,m_left_2,m_left_3,c_left")
    assert diags[-1].message.status[0].values[0].value == "converged"  # type: ignore[union-attr]


def test_output_bag_readable_by_mcap_ros2(replayed: tuple[Path, Path]) -> None:
    reader_mod = pytest.importorskip("mcap_ros2.reader")
    out, _ = replayed
    (mcap,) = out.glob("*.mcap")
    counts: dict[str, int] = {}
    last = None
    for msg in reader_mod.read_ros2_messages(str(mcap)):
        counts[msg.channel.topic] = counts.get(msg.channel.topic, 0) + 1
        if msg.channel.topic == OUTPUT_TOPICS["estimate"]:
            last = msg.ros_msg
    assert counts[OUTPUT_TOPICS["compensated_command"]] == 1500
    assert counts[ENCODER_TOPIC] == 1500
    assert last is not None and len(last.data) == 8


def test_report_files(replayed: tuple[Path, Path]) -> None:
    _, rep = replayed
    for name in ("motion", "tracking_error", "play", "coverage", "characteristic",
                 "convergence", "residuals", "compensation"):  # fmt: skip
        assert (rep / f"{name}.png").stat().st_size > 1000
    page = (rep / "index.html").read_text()
    assert "c_right" in page and "convergence.png" in page
    assert "RMS tracking error without compensation" in page
    assert "paper Example 1" in page  # the bag's truth, from its metadata


def test_replay_keeps_the_bags_custom_data(example_bag: Path, tmp_path: Path) -> None:
    result = replay(
        example_bag,
        tmp_path / "out",
        command_topic=COMMAND_TOPIC,
        encoder_topic=ENCODER_TOPIC,
        joint=JOINT,
    )
    truth = read_truth(result.custom_data)
    assert truth is not None and truth.model == paper_example(1).model


def test_replay_json_and_overrides(
    example_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["replay", str(example_bag), *TOPICS, "-o", str(tmp_path / "o"), "--json"]
    assert main([*args, "--degree", "2", "--no-progress"]) == EXIT_OK
    result = json.loads(capsys.readouterr().out)
    assert set(result["parameters"]) == {
        "m_left_1", "m_left_2", "c_left", "m_right_1", "m_right_2", "c_right"
    }  # fmt: skip
    assert result["compensated"] == 1500 and result["error"] is None


def test_replay_bad_topic_and_params(
    example_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = str(tmp_path / "o")
    assert main(["replay", str(example_bag), "--command", "/x", "--encoder", "/y", "-o", out]) == 2
    err = capsys.readouterr().err
    assert "'/x' is not in" in err and "/encoder (sensor_msgs/msg/JointState" in err
    assert main(["replay", str(example_bag), *TOPICS, "-o", out, "--degree", "0"]) == 2
    assert "degree" in capsys.readouterr().err
    params = tmp_path / "p.yaml"
    params.write_text("backlash_identifier:\n  ros__parameters:\n    model: cascade\n")
    assert main(["replay", str(example_bag), *TOPICS, "-o", out, "--params-file", str(params),
                 "--json", "--no-progress"]) == 0  # fmt: skip
    assert "a_2" in json.loads(capsys.readouterr().out)["parameters"]


def test_truncated_bag_exit_2_and_valid_partial_output(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "dt"
    write_drivetrain_bag(bag, duration=12.0)
    (mcap,) = bag.glob("*.mcap")
    data = mcap.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.7)])
    out = tmp_path / "out"
    code = main(["replay", str(cut), *TOPICS, "-o", str(out), "--no-progress"])
    err = capsys.readouterr().err
    assert code == EXIT_BAD_INPUT
    assert "truncated" in err and "Traceback" not in err
    assert err.strip().count("\n") == 0
    with BagReader(out) as reader:
        assert not reader.salvaged
        n = reader.topics[ENCODER_TOPIC].count
        assert 0 < n < 12_000
        assert reader.topics[OUTPUT_TOPICS["compensated_command"]].count == (
            reader.topics[COMMAND_TOPIC].count
        )


def test_identify_on_a_bag(example_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["identify", str(example_bag), *TOPICS, "--json"]) == EXIT_OK
    result = json.loads(capsys.readouterr().out)
    truth = paper_example(1).backlash
    assert abs(result["backlash"]["c_left"] - truth.c_left) < 0.05
    assert abs(result["backlash"]["m_right"][0] - truth.m_right[0]) < 0.05
    assert main(["identify", str(example_bag)]) == EXIT_BAD_INPUT
    assert "--command TOPIC" in capsys.readouterr().err


def test_replay_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["replay", "--help"])
    assert "/backlash_identifier/estimate" in capsys.readouterr().out


def test_existing_output_needs_overwrite_and_overwrite_spares_non_bags(
    example_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "nested" / "out"  # missing parents are created
    args = ["replay", str(example_bag), *TOPICS, "-o", str(out), "--no-progress"]
    assert main(args) == EXIT_OK
    assert main(args) == EXIT_BAD_INPUT
    assert "exists already" in capsys.readouterr().err
    assert main([*args, "--overwrite"]) == EXIT_OK
    with BagReader(out) as reader:
        assert set(OUTPUT_TOPICS.values()) <= set(reader.topics)
    keep = tmp_path / "notes"
    keep.mkdir()
    (keep / "a.txt").write_text("mine")
    code = main(["replay", str(example_bag), *TOPICS, "-o", str(keep), "--overwrite"])
    assert code == EXIT_BAD_INPUT
    assert "not removing it" in capsys.readouterr().err
    assert (keep / "a.txt").read_text() == "mine"


def _published(bag: Path) -> list[tuple[str, int, bytes]]:
    names = list(OUTPUT_TOPICS.values())
    with BagReader(bag) as reader:
        return [(t, log, bytes(raw)) for t, log, _, raw in reader.raw_messages(names)]


def test_replay_gives_the_same_outputs_on_every_run(example_bag: Path, tmp_path: Path) -> None:
    """Replay identifies on the synchronous worker: each estimate is taken up at the same
    sample on every run, so every compensated command, estimate and report is the same."""
    runs = [
        replay(
            example_bag,
            tmp_path / f"out{k}",
            command_topic=COMMAND_TOPIC,
            encoder_topic=ENCODER_TOPIC,
            joint=JOINT,
        )
        for k in range(2)
    ]
    first, second = (_published(r.output) for r in runs)
    assert first == second
    estimates = {raw for topic, _, raw in first if topic == OUTPUT_TOPICS["estimate"]}
    assert len(estimates) > 5  # the estimate moved during the replay: adoption mattered


def test_a_block_interrupted_while_fed_is_not_fed_again(
    example_bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C while the pipeline takes a block: the interrupt goes up and that block is not
    fed a second time on the way out (it once was: the messages counted twice)."""
    from genbacklash_ros.bags import replay as replay_module

    fed: list[int] = []
    real = replay_module._Feed.block

    def block(self: object, items: list[object]) -> None:
        fed.append(len(items))
        if len(fed) == 1:
            raise KeyboardInterrupt
        real(self, items)  # type: ignore[arg-type]

    monkeypatch.setattr(replay_module._Feed, "block", block)
    with pytest.raises(KeyboardInterrupt):
        replay(
            example_bag,
            tmp_path / "out",
            command_topic=COMMAND_TOPIC,
            encoder_topic=ENCODER_TOPIC,
            joint=JOINT,
        )
    assert len(fed) == 1
