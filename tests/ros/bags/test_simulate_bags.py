"""``genbacklash simulate --bag``: the paper's examples, the random-input drivetrain and the
drivetrain in operation (scenarios, phases) as bags, with their truth in the metadata."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import paper_example
from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    STRAIGHT_BACKLASH,
    OperationSettings,
    operation_record,
)
from genbacklash_ros.bags.bagio import BagError, BagReader, BagWriter, read_custom_data
from genbacklash_ros.bags.simbags import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    JOINT,
    START_NS,
    TRUTH_KEY,
    read_truth,
    write_drivetrain_bag,
    write_example_bag,
    write_operation_bag,
)
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, main
from genbacklash_ros.node.messages import Float64, Float64MultiArray, JointState


def _read(bag: Path) -> tuple[list[tuple[int, object]], list[tuple[int, object]]]:
    with BagReader(bag) as reader:
        items = list(reader.messages([COMMAND_TOPIC, ENCODER_TOPIC]))
    cmd = [(m.log_time_ns, m.message) for m in items if m.topic == COMMAND_TOPIC]
    enc = [(m.log_time_ns, m.message) for m in items if m.topic == ENCODER_TOPIC]
    return cmd, enc


def test_example_bag_holds_the_example(tmp_path: Path) -> None:
    bag = tmp_path / "ex1"
    args = ["simulate", "--example", "1", "--samples", "300", "--seed", "3", "--bag", str(bag)]
    assert main(args) == EXIT_OK
    cmd, enc = _read(bag)
    data = paper_example(1).generate(3, n_samples=300)
    assert len(cmd) == len(enc) == 300
    assert all(isinstance(m, Float64MultiArray) for _, m in cmd)
    assert np.array_equal([m.data[0] for _, m in cmd], data.u)  # type: ignore[union-attr]
    js = [m for _, m in enc]
    assert all(isinstance(m, JointState) and m.name == (JOINT,) for m in js)
    assert np.array_equal([m.position[0] for m in js], data.y)  # type: ignore[union-attr]
    stamps = np.array([m.header.stamp.to_ns() for m in js])  # type: ignore[union-attr]
    assert np.all(np.diff(stamps) == 1_000_000)  # 1 kHz
    log = np.array([t for t, _ in enc])
    assert np.all((log - stamps >= 100_000) & (log - stamps < 300_000))  # received later


def test_drivetrain_bag(tmp_path: Path) -> None:
    bag = tmp_path / "dt"
    args = ["simulate", "--scenario", "drivetrain", "--duration", "2", "--bag", str(bag)]
    assert main(args) == EXIT_OK
    cmd, enc = _read(bag)
    assert len(enc) == 2000
    gaps = np.diff([t for t, _ in cmd]) / 1e6  # ms
    assert gaps.min() >= 0.8 and gaps.max() <= 10.3  # 100-1000 Hz with jitter
    assert np.std(gaps) > 1.0
    first = enc[0][1]
    assert isinstance(first, JointState) and first.name[0] == JOINT and len(first.name) == 2
    assert all(len(m.data) == 2 for _, m in cmd)  # type: ignore[union-attr]


def test_csv_output_unchanged(tmp_path: Path) -> None:
    out = tmp_path / "x.csv"
    assert main(["simulate", "--example", "2", "--samples", "50", "-o", str(out)]) == EXIT_OK
    assert out.read_text().startswith("u,y")


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["simulate", "--scenario", "drivetrain"], "--bag"),
        (["simulate"], "--example"),
        (["simulate", "--example", "1", "--scenario", "drivetrain", "--bag", "B"], "either"),
    ],
)
def test_simulate_option_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    args = [str(tmp_path / a) if a == "B" else a for a in args]
    assert main(args) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1


# --------------------------------------------------------------------------- operation bags


def _operation_settings(**changes: object) -> OperationSettings:
    return OperationSettings(**{"duration": 5.0, "wear": 0.5, **changes})  # type: ignore[arg-type]


def test_operation_bag_round_trip(tmp_path: Path) -> None:
    settings = _operation_settings(loss=0.05)
    made = write_operation_bag(tmp_path / "op", settings, seed=3)
    rec = operation_record(settings, 3)
    with BagReader(made.path) as reader:
        custom = reader.custom_data
        topics = reader.topics
        items = list(reader.messages([COMMAND_TOPIC, ENCODER_TOPIC]))
    # the truth read back is what was written, and it is the record's truth
    assert custom == made.custom_data and set(custom) == {TRUTH_KEY}
    truth = read_truth(custom)
    assert truth is not None
    assert truth.model == rec.truth and truth.model_end == rec.truth_end
    assert truth.seed == 3 and truth.scenario == "operation" and truth.start_ns == START_NS
    assert truth.settings["loss"] == 0.05 and truth.settings["wear"] == 0.5
    assert np.allclose(np.diff(truth.t_s)[:-1], 0.25) and 0 < np.diff(truth.t_s)[-1] <= 0.25
    assert truth.t_s[-1] == pytest.approx(rec.sample_t_ns[-1] / 1e9)
    assert truth.c_left[0] == pytest.approx(rec.c_left[0])
    assert truth.c_right[-1] == pytest.approx(rec.c_right[-1])
    assert truth.c_left[-1] > 1.4 * truth.c_left[0]  # +50 % over the record
    # a bare .mcap keeps the truth too (the metadata embedded in the file)
    (mcap,) = made.path.glob("*.mcap")
    assert read_custom_data(mcap) == custom
    # counts: every command; every reading that arrived, the lost ones absent
    n_enc = int(rec.received.sum())
    assert 0 < rec.received.size - n_enc  # some were lost
    assert topics[COMMAND_TOPIC].count == rec.command_t_ns.size
    assert topics[ENCODER_TOPIC].count == n_enc
    assert made.counts[ENCODER_TOPIC] == (JointState.ros_type, n_enc)
    cmd = [(m.log_time_ns, m.message) for m in items if m.topic == COMMAND_TOPIC]
    enc = [(m.log_time_ns, m.message) for m in items if m.topic == ENCODER_TOPIC]
    assert np.array_equal([t for t, _ in cmd], START_NS + rec.command_t_ns)
    assert np.array_equal([m.data[0] for _, m in cmd], rec.command_u)  # type: ignore[union-attr]
    assert all(len(m.data) == 2 for _, m in cmd)  # type: ignore[union-attr]
    js = [m for _, m in enc]
    assert all(isinstance(m, JointState) and m.name == (JOINT, "wheel_joint") for m in js)
    stamps = np.array([m.header.stamp.to_ns() for m in js])  # type: ignore[union-attr]
    assert np.array_equal(stamps, START_NS + rec.encoder_t_ns)
    assert np.array_equal([m.position[0] for m in js], rec.encoder_y)  # type: ignore[union-attr]
    gaps = np.diff(stamps)
    assert np.any(gaps % 1_000_000 != 0) and np.std(gaps[gaps < 1_500_000]) > 10_000  # jitter
    assert np.any(gaps > 1_500_000)  # a lost reading leaves a hole
    log = np.array([t for t, _ in enc])
    assert np.all((log - stamps >= 100_000) & (log - stamps < 300_000))


def test_simulate_phases_straight_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bag = tmp_path / "ph"
    args = ["simulate", "--phases", "operation:3,one_way:2.5", "--straight", "--loss", "0",
            "--wear", "0", "--noise", "0.001", "--seed", "4", "--bag", str(bag)]  # fmt: skip
    assert main(args) == EXIT_OK
    assert "operation:3,one_way:2.5" in capsys.readouterr().err
    with BagReader(bag) as reader:
        truth = read_truth(reader.custom_data)
        n_enc = reader.topics[ENCODER_TOPIC].count
    assert truth is not None and truth.scenario == "operation:3,one_way:2.5"
    assert truth.model == STRAIGHT_BACKLASH == truth.model_end  # no wear
    assert truth.phases == (("operation", 0.0), ("one_way", 3.0))
    assert truth.settings["phases"] == [["operation", 3.0], ["one_way", 2.5]]
    assert truth.settings["noise"] == 0.001
    assert n_enc == 5500  # 1 kHz, nothing lost


@pytest.mark.parametrize("scenario", ["one_way", "pick_and_place", "sine_sweep"])
def test_simulate_each_scenario(tmp_path: Path, scenario: str) -> None:
    bag = tmp_path / scenario
    args = ["simulate", "--scenario", scenario, "--duration", "2", "--bag", str(bag)]
    assert main(args) == EXIT_OK
    with BagReader(bag) as reader:
        truth = read_truth(reader.custom_data)
        assert reader.topics[COMMAND_TOPIC].count == 200
    assert truth is not None and truth.scenario == scenario
    assert truth.model == OPERATION_BACKLASH
    assert truth.model_end.c_left == pytest.approx(1.2 * OPERATION_BACKLASH.c_left, rel=0.03)


def test_drivetrain_and_example_bags_store_their_truth(tmp_path: Path) -> None:
    made = write_drivetrain_bag(tmp_path / "dt", duration=1.0, wear=0.5)
    with BagReader(made.path) as reader:
        truth = read_truth(reader.custom_data)
    assert truth is not None and truth.scenario == "drivetrain"
    assert truth.model == made.truth and truth.model_end == made.truth_end
    assert truth.c_left[-1] == pytest.approx(1.5 * truth.c_left[0])
    made = write_example_bag(tmp_path / "ex3", 3, n_samples=50)
    with BagReader(made.path) as reader:
        truth = read_truth(reader.custom_data)
    assert truth is not None and truth.model == paper_example(3).model


def test_custom_data_reading_is_tolerant(tmp_path: Path) -> None:
    plain = tmp_path / "plain"
    with BagWriter(plain) as writer:
        writer.write("/x", 1, Float64(1.0))
    with BagReader(plain) as reader:
        assert reader.custom_data is None
    assert read_truth(None) is None and read_truth({}) is None
    assert read_truth({TRUTH_KEY: "{not json"}) is None
    assert read_truth({TRUTH_KEY: '{"format": 1, "scenario": "x"}'}) is None
    # a metadata.yaml whose custom_data is not a string -> string map
    meta = plain / "metadata.yaml"
    text = meta.read_text()
    assert "custom_data: null" in text
    meta.write_text(text.replace("custom_data: null", "custom_data: [1, 2]"))
    assert read_custom_data(plain) is None
    meta.write_text("{{ not yaml")
    assert read_custom_data(plain) is None  # and the MCAP's embedded copy has none either
    with pytest.raises(BagError, match="string keys and values"):
        with BagWriter(tmp_path / "bad") as writer:
            writer.set_custom_data("k", 1)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--phases", "operation:3,bogus:2"], "unknown phase 'bogus'"),
        (["--phases", "operation"], "has no ':SECONDS'"),
        (["--phases", "operation:-1"], "length in seconds > 0"),
        (["--phases", "operation:x"], "length in seconds > 0"),
        (["--phases", "operation:3", "--duration", "4"], "drop --duration"),
        (["--phases", "operation:3", "--scenario", "operation"], "either --scenario or --phases"),
        (["--scenario", "drivetrain", "--loss", "0.1"], "--loss applies to the operation"),
        (["--scenario", "drivetrain", "--straight"], "--straight applies"),
        (["--scenario", "operation", "--snr", "5"], "--snr and --samples"),
        (["--scenario", "operation", "--loss", "2"], "--loss must lie in"),
        (["--scenario", "operation", "--wear", "-1"], "--wear must lie in"),
        (["--scenario", "sine_sweep", "--duration", "0"], "--duration must be > 0"),
        (["--scenario", "operation", "--noise", "-1"], "--noise must be >= 0"),
        (["--example", "1", "--phases", "operation:2"], "either --example or --phases"),
        (["--example", "1", "--duration", "2"], "--duration and --wear apply"),
    ],
)
def test_operation_option_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], args: list[str], message: str
) -> None:
    bag = tmp_path / "b"
    assert main(["simulate", *args, "--bag", str(bag)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
    assert not bag.exists()


def test_phases_without_bag(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["simulate", "--scenario", "operation"]) == EXIT_BAD_INPUT
    assert "give --bag DIR" in capsys.readouterr().err


def test_simulate_help_describes_the_scenarios(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["simulate", "--help"])
    out = capsys.readouterr().out
    for word in ("paper-style random input", "pick_and_place", "--phases", "--straight",
                 "--loss", "genbacklash.truth"):  # fmt: skip
        assert word in out
