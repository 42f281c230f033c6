"""CSV input and structure options on the command line (issue 22, item 8 of the Why): a bad
row is named by its line, ``--drop-nonfinite`` says what it dropped, a short row is never
dropped silently, and ``--degree``/``--na``/``--nb`` take the node parameters' ranges."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from genbacklash_core import paper_example
from genbacklash_ros.bags.csvio import Series, write_series_csv
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_NOT_CONVERGED, EXIT_OK, main

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE1_BAG = ROOT / "bags" / "example1"
TOPICS = ["--command", "/command", "--encoder", "/encoder"]


def _csv(tmp_path: Path, change: dict[int, str] | None = None) -> Path:
    """Example 1 as a CSV, with the lines in ``change`` (1-based, the header is 1) replaced."""
    data = paper_example(1).generate(2)
    path = tmp_path / "ex1.csv"
    write_series_csv(path, Series(u=data.u, y=data.y))
    lines = path.read_text().splitlines()
    for number, text in (change or {}).items():
        lines[number - 1] = text
    path.write_text("\n".join(lines) + "\n")
    return path


def _one_error(capsys: pytest.CaptureFixture[str], command: str) -> str:
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Warning" not in err
    assert err.count("\n") == 1, err
    assert err.startswith(f"genbacklash {command}: error: "), err
    return err


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_a_text_cell_names_its_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    path = _csv(tmp_path, {50: "abc,0.1"})
    assert main([command, str(path)]) == EXIT_BAD_INPUT
    err = _one_error(capsys, command)
    assert "line 50 of" in err and "column 'u': 'abc' is not a number" in err
    assert "index" not in err


@pytest.mark.parametrize("command", ["identify", "diagnose"])
def test_a_short_row_stops_or_is_dropped_and_said(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], command: str
) -> None:
    path = _csv(tmp_path, {7: "0.25"})
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's ConversionWarning: no more
        assert main([command, str(path)]) == EXIT_BAD_INPUT
        assert "line 7 of" in _one_error(capsys, command)
        code = main([command, str(path), "--drop-nonfinite", "--json"])
    assert code in (EXIT_OK, EXIT_NOT_CONVERGED)
    err = capsys.readouterr().err
    assert f"genbacklash {command}: dropped 1 row of {path}" in err and "line 7" in err


def test_drop_nonfinite_names_every_line_it_dropped(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _csv(tmp_path, {10: "nan,0", 11: "0,inf", 300: "x,y"})
    code = main(["identify", str(path), "--drop-nonfinite", "--max-iterations", "5"])
    assert code in (EXIT_OK, EXIT_NOT_CONVERGED)
    err = capsys.readouterr().err
    assert "dropped 3 rows" in err and "lines 10, 11 and 300" in err


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["identify", "{csv}", "--degree", "15"], "--degree 15: parameter 'degree' must lie in"),
        (["identify", "{csv}", "--na", "11"], "--na 11: parameter 'na' must lie in [1, 10]"),
        (["identify", "{csv}", "--nb", "11"], "--nb 11: parameter 'nb' must lie in"),
        (["diagnose", "{csv}", "--start", "degree=15"], "--start degree=15: parameter 'degree'"),
        (["diagnose", "{csv}", "--start", "degree=2,nb=-1"], "parameter 'nb' must lie in"),
        (["identify", "{bag}", *TOPICS, "--command-index", "-1"], "--command-index -1:"),
        (["replay", "{bag}", *TOPICS, "--degree", "10", "-o", "{out}"], "--degree 10: parameter"),
    ],
)  # fmt: skip
def test_structure_options_take_the_node_parameter_ranges(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], argv: list[str], words: str
) -> None:
    path = _csv(tmp_path)
    values = {"{csv}": str(path), "{bag}": str(EXAMPLE1_BAG), "{out}": str(tmp_path / "out")}
    assert main([values.get(a, a) for a in argv]) == EXIT_BAD_INPUT
    assert words in _one_error(capsys, argv[0])
    assert not (tmp_path / "out").exists()


def test_fleet_report_takes_the_play_limit_under_both_names() -> None:
    from genbacklash_ros.cli.main import build_parser

    parser = build_parser("fleet-report")
    for name in ("--play-limit", "--gap-limit"):
        assert parser.parse_args(["fleet-report", "db", name, "0.15"]).gap_limit == 0.15
