"""``genbacklash excite``: the commissioning motion as CSV and bag, the check, the errors."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core.excite import MotionLimits, commissioning_trajectory
from genbacklash_ros.bags.bagio import BagReader
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, START_NS
from genbacklash_ros.cli.excite import EXIT_NOT_CONVERGED
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, build_parser, main
from genbacklash_ros.node.messages import Float64MultiArray

LIMITS = ["--range", "-1.2", "1.2", "--v-max", "3", "--a-max", "30"]


def _one_line_error(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.count("\n") == 1, err
    assert err.startswith("genbacklash excite: error: "), err
    return err.removeprefix("genbacklash excite: error: ").rstrip("\n")


def test_writes_the_csv_and_the_bag_of_the_motion(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv, bag = tmp_path / "motion.csv", tmp_path / "motion_bag"
    assert main(["excite", *LIMITS, "-o", str(csv), "--bag", str(bag)]) == EXIT_OK
    captured = capsys.readouterr()
    expected = commissioning_trajectory(MotionLimits(-1.2, 1.2, 3.0, 30.0))
    # the CSV: t,u with full precision
    assert csv.read_text(encoding="utf-8").splitlines()[0] == "t,u"
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    np.testing.assert_array_equal(table[:, 1], expected.u)
    np.testing.assert_allclose(table[:, 0], np.arange(expected.u.size) / 100.0)
    # the bag: one Float64MultiArray per command on /command, logged at the command's time
    with BagReader(bag) as reader:
        assert reader.topics[COMMAND_TOPIC].msgtype == Float64MultiArray.ros_type
        messages = list(reader.messages([COMMAND_TOPIC]))
    assert len(messages) == expected.u.size
    values = [m.message.data for m in messages if isinstance(m.message, Float64MultiArray)]
    np.testing.assert_array_equal(np.array(values)[:, 0], expected.u)
    stamps = np.array([m.log_time_ns for m in messages]) - START_NS
    np.testing.assert_array_equal(stamps, np.round(np.arange(expected.u.size) * 1e7))
    # the summary: one line on stderr with duration, reversals and the peaks used
    assert captured.out == ""
    summary = captured.err.strip()
    assert "\n" not in summary
    assert "2.84 s" in summary and "3 reversals" in summary
    assert "peak velocity 3 (limit 3)" in summary
    assert "peak acceleration 30 (limit 30)" in summary


def test_check_prints_when_the_identifier_converged(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv = tmp_path / "m.csv"
    argv = ["excite", "--range", "0", "3.1", "--v-max", "2", "--a-max", "20", "-o", str(csv)]
    assert main([*argv, "--check", "--start", "0"]) == EXIT_OK
    out = capsys.readouterr().out
    assert out.startswith("check: the identifier converged after ")
    assert "NRMSE" in out


def test_check_exits_3_when_the_motion_is_too_short(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    csv = tmp_path / "m.csv"
    code = main(["excite", *LIMITS, "-o", str(csv), "--sweeps", "1", "--check"])
    assert code == EXIT_NOT_CONVERGED
    assert "did NOT converge" in capsys.readouterr().out
    assert csv.exists()  # the motion is written all the same


def test_options_shape_the_motion(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    csv, png = tmp_path / "m.csv", tmp_path / "plots" / "m.png"
    argv = [*LIMITS, "--rate", "50", "--gap", "0.1", "--jog-points", "3", "--start", "-1.2"]
    assert main(["excite", *argv, "-o", str(csv), "--plot", str(png)]) == EXIT_OK
    table = np.loadtxt(csv, delimiter=",", skiprows=1)
    expected = commissioning_trajectory(
        MotionLimits(-1.2, 1.2, 3.0, 30.0),
        command_rate=50.0,
        gap_hint=0.1,
        jog_points=3,
        start=-1.2,
    )
    np.testing.assert_array_equal(table[:, 1], expected.u)
    assert table[1, 0] == pytest.approx(0.02)
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "9 reversals" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--range", "1", "-1", "--v-max", "3", "--a-max", "30"], "--range needs LO < HI"),
        (["--range", "a", "1", "--v-max", "3", "--a-max", "30"], "--range LO must be a number"),
        (["--range", "0", "1", "--v-max", "-3", "--a-max", "30"], "--v-max must be > 0"),
        (["--range", "0", "1", "--v-max", "3", "--a-max", "0"], "--a-max must be > 0"),
        (["--range", "0", "1", "--v-max", "nan", "--a-max", "3"], "--v-max must be finite"),
        (["--v-max", "3", "--a-max", "30"], "give the position range: --range LO HI"),
        (["--range", "0", "1", "--a-max", "30"], "give --v-max"),
        ([*LIMITS, "--rate", "0"], "--rate must be > 0"),
        ([*LIMITS, "--gap", "0.5"], "too small for a gap of 0.5"),
        ([*LIMITS, "--start", "5"], r"start 5 lies outside the range \[-1.2, 1.2\]"),
        ([*LIMITS, "--sweeps", "0"], "--sweeps must be >= 1"),
        ([*LIMITS, "--jog-points", "x"], "--jog-points must be a whole number"),
        ([*LIMITS, "--topic", "command"], "--topic must be an absolute topic name"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], message: str
) -> None:
    csv = tmp_path / "m.csv"
    assert main(["excite", *argv, "-o", str(csv)]) == EXIT_BAD_INPUT
    assert re.search(message, _one_line_error(capsys))
    assert not csv.exists()


def test_missing_output_and_an_existing_bag_are_one_line_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["excite", *LIMITS]) == EXIT_BAD_INPUT
    assert _one_line_error(capsys) == "give the output CSV: -o FILE.csv"
    bag = tmp_path / "old_bag"
    bag.mkdir()
    csv = tmp_path / "m.csv"
    assert main(["excite", *LIMITS, "-o", str(csv), "--bag", str(bag)]) == EXIT_BAD_INPUT
    assert "exists already" in _one_line_error(capsys)
    assert not csv.exists()


def test_help_explains_the_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args(["excite", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: genbacklash excite --range LO HI --v-max V --a-max A")
    for text in ("--bag DIR", "--check", "--plot", "t,u", "Float64MultiArray", "Exit status"):
        assert text in out
    with pytest.raises(SystemExit):
        build_parser().parse_args(["--help"])
    assert "excite" in capsys.readouterr().out
