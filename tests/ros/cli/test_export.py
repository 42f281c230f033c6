"""``genbacklash export``: the inverse backlash as a CSV and a C header (issue 22, deliverable 6).

Round trip (the files' values are the core's inverse at the table points, the header
compiles), a known answer on straight branches, the valid range, and bad inputs (exit 2, one
line, no traceback, nothing written).
"""

from __future__ import annotations

import csv
import json
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import (
    Estimate,
    GeneralBacklash,
    Structure,
    branch_inverse,
    compensate,
    paper_example,
)
from genbacklash_core.cascade import model_to_dict
from genbacklash_core.inverse import CompensatorState
from genbacklash_ros.cli.export import inverse_table, read_model, valid_range
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, main
from genbacklash_ros.node.checkpoint import save_checkpoint

CURVED = paper_example(1).model  # curved branches; they cross at u ~ -4.05


def _checkpoint(path: Path, model: GeneralBacklash) -> Path:
    structure = Structure.of(model)
    size = structure.n_parameters
    estimate = Estimate(
        structure, model.parameters(), np.eye(size) * 1e-6, 0.01, 0.5, "converged", 0.9, 1000
    )
    return save_checkpoint(path, estimate, time_ns=5)


def _identify_json(path: Path, model: GeneralBacklash) -> Path:
    out = {**model_to_dict(model), "iterations": 4, "converged": True, "fit": {"nrmse": 0.1}}
    path.write_text(json.dumps(out))
    return path


def read_csv(path: Path) -> tuple[list[str], np.ndarray]:
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    return rows[0], np.array(rows[1:], dtype=float)


def read_header(path: Path, name: str = "genbacklash_inverse") -> dict[str, np.ndarray]:
    text = path.read_text()
    arrays = {}
    for column in ("x", "u_up", "u_down"):
        match = re.search(rf"static const double {name}_{column}\[\w+\] = \{{(.*?)\}};", text, re.S)
        assert match, column
        arrays[column] = np.array([float(v) for v in match.group(1).split(",")])
    return arrays


@pytest.mark.parametrize("source", ["checkpoint", "identify"])
def test_round_trip_equals_the_core_inverse(
    source: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    model_file = (_checkpoint if source == "checkpoint" else _identify_json)(
        tmp_path / "model.json", CURVED
    )
    out = tmp_path / "tables" / "joint1"
    code = main(["export", str(model_file), "-o", str(out), "--range", "-1", "1.5"])
    err = capsys.readouterr().err
    assert code == EXIT_OK, err
    assert f"{out}.csv" in err and f"{out}.h" in err and "256 points" in err
    header, rows = read_csv(out.with_suffix(".csv"))
    assert header == ["x_rad", "u_up_rad", "u_down_rad"]
    x = rows[:, 0]
    assert x.size == 256 and x[0] == -1.0 and x[-1] == 1.5
    np.testing.assert_allclose(np.diff(x), 2.5 / 255, rtol=1e-9)
    options = valid_range(CURVED).options()
    up = branch_inverse(CURVED, x, +1, options)
    down = branch_inverse(CURVED, x, -1, options)
    np.testing.assert_allclose(rows[:, 1], up, rtol=0, atol=1e-12)
    np.testing.assert_allclose(rows[:, 2], down, rtol=0, atol=1e-12)
    # the branches map them back: R(u_up) = x, L(u_down) = x (increasing branches)
    np.testing.assert_allclose(CURVED.right(rows[:, 1]), x, atol=1e-12)
    np.testing.assert_allclose(CURVED.left(rows[:, 2]), x, atol=1e-12)
    c = read_header(out.with_suffix(".h"))
    np.testing.assert_allclose(c["x"], x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(c["u_up"], up, rtol=0, atol=1e-12)
    np.testing.assert_allclose(c["u_down"], down, rtol=0, atol=1e-12)
    text = out.with_suffix(".h").read_text()
    assert "#define GENBACKLASH_INVERSE_POINTS 256" in text
    assert "#define GENBACKLASH_INVERSE_X_MIN -1.0" in text
    assert "#define GENBACKLASH_INVERSE_X_MAX 1.5" in text
    for words in ("direction of motion", "Interpolate linearly", "Clamp x"):
        assert words in text


def test_the_table_is_what_the_compensator_sends() -> None:
    """Moving up through the table points the compensator sends the up column; moving down
    the down column (the stateful inverse, root solve per step)."""
    table = inverse_table(CURVED, 41, (-1.0, 1.0))
    options = table.valid.options()
    rising = CompensatorState.initial(CURVED, x0=-1.2, options=options)
    np.testing.assert_allclose(
        compensate(CURVED, table.x, options, state=rising), table.up, atol=1e-9
    )
    falling = CompensatorState.initial(CURVED, x0=1.2, options=options)
    sent = compensate(CURVED, table.x[::-1], options, state=falling)
    np.testing.assert_allclose(sent[::-1], table.down, atol=1e-9)


def test_known_answer_straight_branches(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """GeneralBacklash.ideal: the inverse is x + c_R going up, x - c_L going down."""
    c_left, c_right = 0.03, 0.05
    model = GeneralBacklash.ideal(1.0, c_left, c_right)
    path = _checkpoint(tmp_path / "ideal.json", model)
    out = tmp_path / "ideal.csv"
    argv = ["export", str(path), "-o", str(out), "--format", "csv", "--points", "11"]
    assert main([*argv, "--range", "-0.5", "0.5"]) == EXIT_OK
    capsys.readouterr()
    assert not out.with_suffix(".h").exists()
    _, rows = read_csv(out)
    x = np.linspace(-0.5, 0.5, 11)
    np.testing.assert_allclose(rows[:, 0], x, atol=1e-15)
    np.testing.assert_allclose(rows[:, 1], x + c_right, atol=1e-12)
    np.testing.assert_allclose(rows[:, 2], x - c_left, atol=1e-12)
    # a slope of 2: up (x / 2 + c_R), down (x / 2 - c_L)
    steep = inverse_table(GeneralBacklash.ideal(2.0, c_left, c_right), 5, (-1.0, 1.0))
    np.testing.assert_allclose(steep.up, steep.x / 2 + c_right, atol=1e-12)
    np.testing.assert_allclose(steep.down, steep.x / 2 - c_left, atol=1e-12)


def test_decreasing_branches_up_is_the_left_branch() -> None:
    """Paper Example 2 (decreasing branches): moving the load up takes the left branch."""
    model = paper_example(2).model
    table = inverse_table(model, 21, (-0.5, 0.5))
    np.testing.assert_allclose(model.left(table.up), table.x, atol=1e-12)
    np.testing.assert_allclose(model.right(table.down), table.x, atol=1e-12)


def test_the_valid_range_ends_where_the_branches_turn_or_cross() -> None:
    # slopes 1 - 3 (u +/- 0.1)^2 vanish at |u + -0.1| = 1/sqrt(3): the branches turn there
    turning = GeneralBacklash((1.0, 0.0, -1.0), 0.1, (1.0, 0.0, -1.0), 0.1)
    valid = valid_range(turning)
    edge = 1 / np.sqrt(3) - 0.1
    np.testing.assert_allclose(valid.commands, (-edge, edge), rtol=1e-12)
    left_low = float(turning.left(-edge))
    right_high = float(turning.right(edge))
    np.testing.assert_allclose(valid.positions, (left_low, right_high), rtol=1e-12)
    table = inverse_table(turning, 5)  # bounded: the whole valid range by default
    assert table.range == valid.positions
    # Example 1's branches cross at u ~ -4.05: the valid range stops there, open above
    crossing = valid_range(CURVED)
    assert crossing.commands[1] == np.inf and not crossing.bounded
    where = max(CURVED.crossings(-20.0, 0.0))  # (and -20: the branches are crossed there)
    assert where == pytest.approx(-4.0486, abs=1e-4)
    assert crossing.commands[0] == where
    assert crossing.positions[0] == pytest.approx(float(CURVED.left(where)), abs=1e-9)


def test_the_c_header_compiles(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    compiler = shutil.which("cc")
    if compiler is None:
        pytest.skip("no C compiler (cc) found")
    path = _checkpoint(tmp_path / "model.json", CURVED)
    header = tmp_path / "joint.h"
    code = main(
        ["export", str(path), "-o", str(header), "--format", "c", "--range", "-1", "1",
         "--name", "joint1_inverse"]
    )  # fmt: skip
    assert code == EXIT_OK, capsys.readouterr().err
    assert read_header(header, "joint1_inverse")["x"].size == 256
    main_c = tmp_path / "use.c"
    main_c.write_text(
        '#include "joint.h"\n'
        "double lookup(double x, int up) {\n"
        "  const double *col = up ? joint1_inverse_u_up : joint1_inverse_u_down;\n"
        "  double s;\n"
        "  unsigned int k;\n"
        "  if (x < JOINT1_INVERSE_X_MIN) x = JOINT1_INVERSE_X_MIN;\n"
        "  if (x > JOINT1_INVERSE_X_MAX) x = JOINT1_INVERSE_X_MAX;\n"
        "  s = (x - joint1_inverse_x_min) / (joint1_inverse_x_max - joint1_inverse_x_min)\n"
        "      * (joint1_inverse_points - 1);\n"
        "  k = (unsigned int)s;\n"
        "  if (k > JOINT1_INVERSE_POINTS - 2) k = JOINT1_INVERSE_POINTS - 2;\n"
        "  return col[k] + (s - k) * (col[k + 1] - col[k]);\n"
        "}\n"
    )
    for source in (header, main_c):
        run = subprocess.run(
            [compiler, "-fsyntax-only", "-std=c99", "-Wall", "-Wextra", "-pedantic", "-Werror",
             "-Wno-unused-const-variable", str(source)],
            capture_output=True, text=True, check=False, cwd=tmp_path,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr


def _bad_inputs(tmp_path: Path) -> dict[str, tuple[list[str], str]]:
    good = _checkpoint(tmp_path / "good.json", CURVED)
    not_json = tmp_path / "data.csv"
    not_json.write_text("u,y\n0,0\n")
    no_model = tmp_path / "other.json"
    no_model.write_text(json.dumps({"steps": [], "gap_initial": 0.1}))
    broken = tmp_path / "broken.json"
    broken.write_text(json.dumps({"model": "backlash", "backlash": {"m_left": [1.0]}}))
    corrupt = tmp_path / "corrupt.json"
    corrupt.write_text(json.dumps({"format": "genbacklash-checkpoint", "version": 1}))
    out = str(tmp_path / "out" / "table")
    folder = tmp_path / "folder"
    folder.mkdir()
    rng = ["--range", "-1", "1"]
    return {
        "missing file": (
            ["export", str(tmp_path / "nope.json"), "-o", out, *rng],
            "does not exist",
        ),
        "not JSON": (["export", str(not_json), "-o", out, *rng], "is not JSON"),
        "JSON without a model": (["export", str(no_model), "-o", out, *rng], "holds no model"),
        "a model missing a field": (["export", str(broken), "-o", out, *rng], "not a valid model"),
        "a corrupt checkpoint": (["export", str(corrupt), "-o", out, *rng], "not a usable"),
        "a directory": (["export", str(folder), "-o", out, *rng], "is a directory"),
        "-o a directory": (["export", str(good), "-o", str(folder), *rng], "is a directory"),
        "-o .": (["export", str(good), "-o", ".", *rng], "is a directory"),
        "--points 1": (["export", str(good), "-o", out, "--points", "1", *rng], "--points"),
        "--points x": (["export", str(good), "-o", out, "--points", "x", *rng], "--points"),
        "range outside": (
            ["export", str(good), "-o", out, "--range", "-20", "1"],
            "outside the valid range",
        ),
        "range reversed": (["export", str(good), "-o", out, "--range", "1", "-1"], "LO < HI"),
        "range not numbers": (["export", str(good), "-o", out, "--range", "a", "1"], "two numbers"),
        "unbounded without range": (["export", str(good), "-o", out], "give --range"),
        "bad C name": (["export", str(good), "-o", out, *rng, "--name", "1x"], "C identifier"),
    }


CASES = [
    "missing file",
    "not JSON",
    "JSON without a model",
    "a model missing a field",
    "a corrupt checkpoint",
    "a directory",
    "-o a directory",
    "-o .",
    "--points 1",
    "--points x",
    "range outside",
    "range reversed",
    "range not numbers",
    "unbounded without range",
    "bad C name",
]


@pytest.mark.parametrize("case", CASES)
def test_bad_input_exits_2_with_one_line(
    case: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv, words = _bad_inputs(tmp_path)[case]
    assert main(argv) == EXIT_BAD_INPUT
    out, err = capsys.readouterr()
    assert err.startswith("genbacklash export: error: "), err
    assert words in err and err.count("\n") == 1 and "Traceback" not in err, err
    assert out == ""
    assert not list((tmp_path / "out").glob("table*"))


def test_outputs_may_not_overwrite_the_model(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """-o names the files by their suffix; the one that would be the model is refused."""
    model = _identify_json(tmp_path / "model.csv", CURVED)  # a model file with a .csv name
    before = model.read_bytes()
    assert main(["export", str(model), "-o", str(tmp_path / "model"), "--range", "-1", "1"]) == 2
    err = capsys.readouterr().err
    assert "is the input MODEL" in err and err.count("\n") == 1, err
    assert model.read_bytes() == before
    assert not (tmp_path / "model.h").exists()


def test_help_explains(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["export", "--help"])
    assert stop.value.code == 0
    text = capsys.readouterr().out
    for words in ("valid range", "checkpoint", "identify --json", "u_up", "interpolate", "--range"):
        assert words in text, words


def test_read_model_takes_every_offline_result(tmp_path: Path) -> None:
    """A checkpoint, identify's --json, and replay's --json (its "model" entry)."""
    replayed = tmp_path / "replay.json"
    replayed.write_text(json.dumps({"state": "converged", "model": model_to_dict(CURVED)}))
    sources = {
        "checkpoint": _checkpoint(tmp_path / "cp.json", CURVED),
        "identify output": _identify_json(tmp_path / "id.json", CURVED),
        "replay output": replayed,
    }
    for kind, path in sources.items():
        assert read_model(path) == (CURVED, kind)
