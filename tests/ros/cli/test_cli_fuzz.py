"""Fuzzing the command line (issue 22, deliverable 2 "Nothing silent"): commands, arguments
and small input files -- CSVs of random cells, the bundled bag cut short or with bytes
garbled -- through :func:`genbacklash_ros.cli.main.main`, in process.

For every example: no traceback (no exception escapes ``main``, nothing on stderr reads
``Traceback``), an exit status in {0, 2, 3} (argparse's own usage errors are 2), never
status 0 with a NaN (or an infinity) in the JSON printed, and every input file byte for byte
as before (hashed before and after). Derandomised (a fixed example sequence), so a failure
reproduces; ``GENBACKLASH_FUZZ_SCALE=10`` multiplies the number of examples.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import shutil
import tempfile
import warnings
from pathlib import Path
from typing import Any

import pytest
from hypothesis import HealthCheck, Phase, event, given, settings
from hypothesis import strategies as st

from genbacklash_ros.cli.main import main

ROOT = Path(__file__).resolve().parents[3]
BAG = ROOT / "bags" / "example1"  # 6000 messages, one joint: cheap enough to replay
SCALE = int(os.environ.get("GENBACKLASH_FUZZ_SCALE", "1"))
OK_CODES = {0, 2, 3}

# ------------------------------------------------------------------ inputs

_CELLS = st.one_of(
    st.floats(-2.0, 2.0, allow_nan=False).map(repr),
    st.sampled_from(["", "nan", "inf", "-inf", "abc", "1e400", " 0.5 ", "1,5", '"2"', "0x10"]),
    st.integers(-3, 3).map(str),
)


@st.composite
def csv_text(draw: st.DrawFn) -> str:
    """A small CSV: a header (mostly u,y or t,u,y; sometimes other names or none) and rows
    of a backlash's input and output (the play operator, so that identification can work)
    with a few random bad cells, short rows, comments or blank lines put in."""
    header = draw(
        st.sampled_from(["u,y"] * 4 + ["t,u,y"] * 2 + ["y,u,extra", "u,position", "", "u;y"])
    )
    names = header.split(",") if header else ["u", "y"]
    n = draw(st.one_of(st.integers(0, 20), st.integers(250, 400)))
    rows = []
    x = 0.0
    for k in range(n):
        u = 1.5 * math.sin(0.05 * k) + 0.4 * math.sin(0.31 * k)
        x = min(max(x, u - 0.2), u + 0.3)  # the play operator: c_L = 0.3, c_R = 0.2
        values = {"t": repr(0.001 * k), "u": repr(u), "y": repr(x), "extra": "1"}
        rows.append(",".join(values.get(name, "0") for name in names))
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 2, 3]))):
        where = draw(st.integers(0, len(rows)))
        rows.insert(where, ",".join(draw(st.lists(_CELLS, min_size=0, max_size=4))))
    return "\n".join([header, *rows]) + draw(st.sampled_from(["\n", "", "\n\n"]))


@st.composite
def bag_change(draw: st.DrawFn) -> tuple[str, float, int]:
    """How to damage the bundled bag: keep it, cut it at a fraction, or garble bytes."""
    kind = draw(st.sampled_from(["intact", "intact", "cut", "garble", "bare"]))
    return kind, draw(st.floats(0.0, 1.0)), draw(st.integers(1, 64))


def _make_bag(root: Path, change: tuple[str, float, int]) -> Path:
    kind, fraction, count = change
    (mcap,) = BAG.glob("*.mcap")
    if kind == "intact":
        shutil.copytree(BAG, root / "bag")
        return root / "bag"
    data = bytearray(mcap.read_bytes())
    if kind == "cut":
        data = data[: int(len(data) * fraction)]
    elif kind == "garble":
        start = int(len(data) * fraction)
        for k in range(start, min(start + count * 97, len(data)), 97):
            data[k] ^= 0xA5
    path = root / "bag.mcap"
    path.write_bytes(bytes(data))
    return path


# ------------------------------------------------------------------ arguments

_OPTIONS: dict[str, list[list[str]]] = {
    "bag": [
        ["--command", "/command", "--encoder", "/encoder"],
        ["--command", "/command", "--encoder", "/encoder"],
        ["--command", "/command", "--encoder", "/encoder"],
        ["--command", "/command", "--encoder", "/encoder", "--joint", "drive_joint"],
        ["--command", "/command", "--encoder", "/encoder", "--joint", "Elbow"],
        ["--command", "/command", "--encoder", "/encoder", "--command-index", "3"],
        ["--command", "/command", "--encoder", "/encoder", "--command-index", "-1"],
        ["--command", "/cmd", "--encoder", "/encoder"],
        ["--command", "/encoder", "--encoder", "/command"],
        ["--command", "/command", "--encoder", "/command"],
        [],
    ],
    "structure": [
        [],
        [],
        [],
        [],
        ["--degree", "1"],
        ["--degree", "2"],
        ["--degree", "0"],
        ["--degree", "15"],
        ["--model", "cascade", "--na", "2", "--nb", "1"],
        ["--na", "11"],
        ["--param", "degree=2"],
        ["--param", "degree=x"],
        ["--param", "window=abc"],
        ["--param", "nonsense=1"],
        ["--param", "="],
        ["--param", "joint="],
        ["--param", "degree=2", "--degree", "3"],
    ],
}
_IDENTIFY = [[], ["--json"], ["--drop-nonfinite"], ["--json", "--drop-nonfinite"],
             ["--sign", "-1"], ["--no-refine"]]  # fmt: skip
_DIAGNOSE = [[], ["--json"], ["--json"], ["--drop-nonfinite", "--json"], ["--validation", "0.5"],
             ["--validation", "1.5"], ["--start", "degree=2"], ["--start", "degree=x"],
             ["--start", "{missing}"]]  # fmt: skip
_REPLAY = [["--json"], [], ["--method", "recursive", "--json"], ["--param", "gate_low=0.3"]]


@st.composite
def command_line(draw: st.DrawFn) -> tuple[str, list[str], Any]:
    """``(command, options, input)``: input is CSV text or a bag change."""
    command = draw(st.sampled_from(["identify", "diagnose", "replay"]))
    on_bag = command == "replay" or draw(st.booleans())
    source: Any = draw(bag_change()) if on_bag else draw(csv_text())
    options = list(draw(st.sampled_from(_OPTIONS["bag"]))) if on_bag else []  # a copy
    if command != "diagnose":
        options = options + draw(st.sampled_from(_OPTIONS["structure"]))
    if command == "identify":
        options += [*draw(st.sampled_from(_IDENTIFY)), "--max-iterations", "4"]
    elif command == "diagnose":
        options += draw(st.sampled_from(_DIAGNOSE))
    else:
        options += [*draw(st.sampled_from(_REPLAY)), "--no-progress"]
    return command, options, source


# ------------------------------------------------------------------ checks


def _digest(path: Path) -> dict[str, str]:
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    return {str(f): hashlib.sha256(f.read_bytes()).hexdigest() for f in files if f.exists()}


def _no_nan(text: str) -> list[str]:
    """The non-finite constants (NaN, Infinity) in the JSON printed on stdout: one object
    (fleet-report's, indented) or one per line (identify, diagnose, replay)."""
    found: list[str] = []
    try:
        json.loads(text, parse_constant=found.append)
    except json.JSONDecodeError:
        for line in text.splitlines():
            if line.startswith("{"):
                json.loads(line, parse_constant=found.append)
    return found


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse: a usage error (2)
        code = exit_.code if isinstance(exit_.code, int) else 2
    captured = capsys.readouterr()
    return code, captured.out, captured.err


@settings(
    max_examples=100 * SCALE,
    derandomize=True,
    database=None,
    deadline=None,
    phases=(Phase.explicit, Phase.reuse, Phase.generate, Phase.shrink),
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(case=command_line())
def test_the_command_line_never_crashes_hides_nan_or_touches_its_input(
    capsys: pytest.CaptureFixture[str], case: tuple[str, list[str], Any]
) -> None:
    command, options, source = case
    capsys.readouterr()
    with tempfile.TemporaryDirectory(prefix="genbacklash-fuzz-") as tmp:
        root = Path(tmp)
        if isinstance(source, str):
            data = root / "data.csv"
            data.write_text(source, encoding="utf-8")
        else:
            data = _make_bag(root, source)
        argv = [command, str(data)]
        if command == "replay":
            argv += ["-o", str(root / "out")]
        argv += [str(root / "missing.json") if o == "{missing}" else o for o in options]
        before = _digest(data)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # printed by the CLI, not raised
            code, out, err = _run(argv, capsys)
        event(f"{command} on {'a CSV' if isinstance(source, str) else 'a bag'}: exit {code}")
        assert "Traceback" not in err, (argv, err)
        assert code in OK_CODES, (argv, code, err)
        if code == 0:
            assert not _no_nan(out), (argv, out)
        if code == 2 and "usage:" not in err:
            assert err.strip().splitlines()[-1].startswith(f"genbacklash {command}: error: "), (
                argv,
                err,
            )
        assert _digest(data) == before, argv


@st.composite
def fleet_case(draw: st.DrawFn) -> tuple[list[tuple[str, tuple[str, float, int]]], list[str]]:
    """An archive (bags at paths, some damaged; or none, or a stray file) and options."""
    bags = draw(
        st.lists(
            st.tuples(st.sampled_from(["r1/2024-03-01", "r1/2024-03-02", "r2/j/run.mcap"]),
                      bag_change()),
            max_size=2,
            unique_by=lambda item: item[0],
        )
    )  # fmt: skip
    options = draw(
        st.sampled_from(
            [[], [], ["--command", "/cmd"], ["--encoder", "/command"], ["--joint", "Elbow"],
             ["--param", "degree=2"], ["--replay", "--no-diagnose"], ["--validation", "2"]]
        )
    )  # fmt: skip
    return bags, options


@settings(
    max_examples=10 * SCALE,
    derandomize=True,
    database=None,
    deadline=None,
    phases=(Phase.explicit, Phase.reuse, Phase.generate),  # a fleet run is seconds: no shrink
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(case=fleet_case())
def test_fleet_and_its_report_never_crash_hide_nan_or_touch_the_archive(
    capsys: pytest.CaptureFixture[str],
    case: tuple[list[tuple[str, tuple[str, float, int]]], list[str]],
) -> None:
    bags, options = case
    capsys.readouterr()
    with tempfile.TemporaryDirectory(prefix="genbacklash-fuzz-") as tmp:
        root = Path(tmp)
        archive = root / "archive"
        archive.mkdir()
        (archive / "notes.txt").write_text("not a bag")
        for k, (where, change) in enumerate(bags):
            (root / f"made{k}").mkdir()
            made = _make_bag(root / f"made{k}", change)
            target = archive / where
            target.parent.mkdir(parents=True, exist_ok=True)
            if made.is_dir() and where.endswith(".mcap"):
                (mcap,) = made.glob("*.mcap")
                made = mcap
            elif not made.is_dir() and not where.endswith(".mcap"):
                target = target / "data.mcap"
                target.parent.mkdir(parents=True, exist_ok=True)
            shutil.move(str(made), target)
        before = _digest(archive)
        db = root / "fleet.db"
        argv = ["fleet", str(archive), "--db", str(db), "--threads", "--workers", "1"]
        code, out, err = _run([*argv, "--no-progress", *options], capsys)
        event(f"fleet with {len(bags)} bags: exit {code}")
        assert "Traceback" not in err, (bags, options, err)
        assert code in {0, 2}, (bags, options, code, err)
        if code == 0:
            report = ["fleet-report", str(db), "--gap-limit", "2", "-o", str(root / "rep")]
            code, out, err = _run([*report, "--json"], capsys)
            event(f"fleet-report: exit {code}")
            assert "Traceback" not in err and code in OK_CODES, err
            if code == 0:
                assert not _no_nan(out), out
        assert _digest(archive) == before, (bags, options)
