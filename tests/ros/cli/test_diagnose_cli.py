"""``genbacklash diagnose``: the JSON contract, the report, --start, exit codes and messages."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core.diagnose import StartStructure, synthetic_case
from genbacklash_ros.bags.csvio import Series, write_series_csv
from genbacklash_ros.cli.diagnose import parse_start
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, main


def _csv(tmp_path: Path, effects: list[str], seed: int, n: int = 1500) -> Path:
    case = synthetic_case(effects, seed, n)
    path = tmp_path / f"{'_'.join(effects) or 'clean'}_{seed}.csv"
    write_series_csv(path, Series(case.u, case.y))
    return path


def test_json_contract(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _csv(tmp_path, ["time_delay"], 41)
    assert main(["diagnose", str(data), "--json"]) == EXIT_OK
    result = json.loads(capsys.readouterr().out)
    old = {"steps", "gap_initial", "gap_final", "gap_floor", "model"}
    # issue 22: one word for the validation NRMSE, "misfit"; the old keys stay (GUIDE §4)
    assert set(result) == old | {"misfit_initial", "misfit_final", "misfit_floor", "unexplained"}
    for name in ("initial", "final", "floor"):
        assert result[f"misfit_{name}"] == result[f"gap_{name}"]
    assert [step["effect"] for step in result["steps"]] == ["time_delay"]
    step = result["steps"][0]
    assert set(step) == {
        "effect", "evidence", "gap_before", "gap_after", "misfit_before", "misfit_after"
    }  # fmt: skip
    assert (step["misfit_before"], step["misfit_after"]) == (step["gap_before"], step["gap_after"])
    assert step["gap_before"] == result["gap_initial"] > step["gap_after"] == result["gap_final"]
    backlash = result["model"]["backlash"]
    assert result["model"]["play"] == backlash["c_left"] + backlash["c_right"]
    assert result["model"]["fit"]["misfit"] == result["model"]["fit"]["nrmse"]
    assert "dead time" in step["evidence"]
    model = result["model"]
    assert model["model"] == "backlash" and model["delay"] >= 2
    assert set(model["backlash"]) == {"m_left", "c_left", "m_right", "c_right"}
    assert model["offset"] == 0.0 and model["drift"] is None and model["saturation"] is None


def test_text_output_and_report(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _csv(tmp_path, ["gap_drift"], 42)
    out_dir = tmp_path / "report"
    assert main(["diagnose", str(data), "--report", str(out_dir)]) == EXIT_OK
    captured = capsys.readouterr()
    assert "step 1: gap_drift - misfit " in captured.out and "final model" in captured.out
    assert "final misfit " in captured.out and " gap " not in captured.out
    # a CSV without t: the drift per sample, saying how to get it per second
    assert "rad per sample (no time stamps: a t column gives rad/s)" in captured.out
    assert "per time" not in captured.out
    for name in (
        "fit_steps.png",
        "misfit_steps.png",
        "misfit_breakdown.png",
        "misfit_map.png",
        "correlations.png",
        "step_error.png",
        "summary.md",
        "index.html",
    ):
        assert (out_dir / name).stat().st_size > 0, name
        assert f"wrote {out_dir / name}" in captured.err
    assert not (out_dir / "report.html").exists()  # the page is index.html, as every report
    summary = (out_dir / "summary.md").read_text(encoding="utf-8")
    assert "| 1 | gap_drift |" in summary and "![misfit_steps.png](misfit_steps.png)" in summary
    page = (out_dir / "index.html").read_text(encoding="utf-8")
    assert '<img src="fit_steps.png"' in page
    assert "<td>gap_drift</td>" in page and "|---|" not in page and "**" not in page


def test_start_from_identify_json_and_from_a_structure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = _csv(tmp_path, ["curved_branches"], 43)
    assert main(["identify", str(data), "--degree", "3", "--json"]) in (0, 3)
    start = tmp_path / "start.json"
    start.write_text(capsys.readouterr().out, encoding="utf-8")
    assert main(["diagnose", str(data), "--json", "--start", str(start)]) == EXIT_OK
    from_json = json.loads(capsys.readouterr().out)
    assert len(from_json["model"]["backlash"]["m_left"]) >= 3
    assert "curved_branches" not in [s["effect"] for s in from_json["steps"]]
    assert (
        main(["diagnose", str(data), "--json", "--start", "degree=3", "--validation", "0.2"]) == 0
    )
    assert "curved_branches" not in [
        s["effect"] for s in json.loads(capsys.readouterr().out)["steps"]
    ]


def test_parse_start() -> None:
    assert parse_start("degree=3,na=2,nb=1") == StartStructure(3, 2, 1)
    assert parse_start("degree=2") == StartStructure(2)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--start", "degree=three"], "degree must be a whole number"),
        (["--start", "order=3"], "unknown key 'order'"),
        (["--start", "missing.json"], "neither degree="),
    ],
)
def test_bad_start_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], extra: list[str], message: str
) -> None:
    data = _csv(tmp_path, [], 44, n=400)
    assert main(["diagnose", str(data), *extra]) == EXIT_BAD_INPUT
    assert message in capsys.readouterr().err


def test_bad_json_start_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _csv(tmp_path, [], 44, n=400)
    start = tmp_path / "start.json"
    start.write_text("[1, 2]", encoding="utf-8")
    assert main(["diagnose", str(data), "--start", str(start)]) == EXIT_BAD_INPUT
    assert "must hold a JSON object" in capsys.readouterr().err
    start.write_text('{"model": "backlash"}', encoding="utf-8")
    assert main(["diagnose", str(data), "--start", str(start)]) == EXIT_BAD_INPUT
    assert "not a model description" in capsys.readouterr().err


def test_bags_without_topics_and_missing_files_exit_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["diagnose", str(tmp_path / "run.mcap")]) == EXIT_BAD_INPUT
    assert "--command TOPIC and --encoder TOPIC" in capsys.readouterr().err
    assert main(["diagnose", str(tmp_path / "none.csv")]) == EXIT_BAD_INPUT
    assert "does not exist" in capsys.readouterr().err


def test_diagnose_reads_a_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, write_example_bag

    bag = tmp_path / "ex1"
    write_example_bag(bag, 1, seed=3, n_samples=1500)
    args = ["diagnose", str(bag), "--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC]
    assert main([*args, "--json"]) == EXIT_OK
    result = json.loads(capsys.readouterr().out)
    assert [step["effect"] for step in result["steps"]] == ["curved_branches"]


def test_an_operation_bag_is_read_as_the_node_reads_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The drivetrain in operation, as a bag: the samples diagnose works on are the node's
    (the command held at each reading's stamp, a break after every lost reading); a clean
    record names nothing and the report says what the floor is and where the gap sits."""
    from genbacklash_core.scenarios import STRAIGHT_BACKLASH, OperationSettings, operation_record
    from genbacklash_ros.bags.bagio import read_aligned
    from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, write_operation_bag

    settings = OperationSettings(duration=8.0, model=STRAIGHT_BACKLASH, loss=0.03)
    bag = tmp_path / "operation"
    write_operation_bag(bag, settings, seed=3)
    u, y, breaks = operation_record(settings, 3).series()
    series = read_aligned(bag, COMMAND_TOPIC, ENCODER_TOPIC, joint="drive_joint")
    np.testing.assert_array_equal(series.u, u)
    np.testing.assert_array_equal(series.y, y)
    np.testing.assert_array_equal(series.breaks, breaks)
    assert 100 < int(np.sum(breaks)) < 500  # ~3% lost: each loss breaks the chain
    args = ["diagnose", str(bag), "--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC]
    args += ["--joint", "drive_joint"]
    assert main([*args, "--json"]) == EXIT_OK
    result = json.loads(capsys.readouterr().out)
    assert result["steps"] == []
    assert 0.0 < result["gap_floor"] and result["gap_initial"] < 2.0 * result["gap_floor"]
    out_dir = tmp_path / "report"
    assert main([*args, "--report", str(out_dir)]) == EXIT_OK
    captured = capsys.readouterr()
    assert "floor: quantisation and noise allow a misfit of" in captured.out
    summary = (out_dir / "summary.md").read_text(encoding="utf-8")
    assert "**Floor**: quantisation and noise allow" in summary
    assert "| position range [rad] | start |" in summary
    assert "| validation samples | start |" in summary
    assert (out_dir / "misfit_map.png").stat().st_size > 0


def test_validation_fraction_is_checked(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["diagnose", "data.csv", "--validation", "1.5"])
    assert exit_info.value.code == 2
    assert "must be in (0, 1)" in capsys.readouterr().err


def test_help_explains(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["diagnose", "--help"])
    text = capsys.readouterr().out
    for word in ("curved_branches", "saturation", "--validation", "--start", "--report", "gap"):
        assert word in text


def test_drift_rate_per_second(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A record with stamps (a t column, 2 ms apart) gives the drift rate in rad/s; the JSON
    keeps the rate per sample and adds rate_per_s (issue 22: not "per time")."""
    case = synthetic_case(["gap_drift"], 42, 1500)
    path = tmp_path / "stamped.csv"
    write_series_csv(path, Series(case.u, case.y, t=np.arange(case.u.size) * 0.002))
    assert main(["diagnose", str(path), "--json"]) == EXIT_OK
    drift = json.loads(capsys.readouterr().out)["model"]["drift"]
    assert drift["basis"] == "time"
    assert drift["rate_per_s"] == pytest.approx(drift["rate"] / 0.002)
    assert main(["diagnose", str(path)]) == EXIT_OK
    text = capsys.readouterr().out
    line = next(row for row in text.splitlines() if "drift rate" in row)
    assert f"{drift['rate_per_s']:.4g} rad/s" in line and "rad per sample of 2 ms" in line
