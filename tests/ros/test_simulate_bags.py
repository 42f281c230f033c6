"""``genbacklash simulate --bag``: the paper's examples and the drivetrain scenario as bags."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import paper_example
from genbacklash_ros.bagio import BagReader
from genbacklash_ros.cli import EXIT_BAD_INPUT, EXIT_OK, main
from genbacklash_ros.messages import Float64MultiArray, JointState
from genbacklash_ros.simbags import COMMAND_TOPIC, ENCODER_TOPIC, JOINT


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
