"""No command destroys its input; outputs are checked before the work (issue 22, items 1-3).

Every writing command is run with each of its outputs pointed at an input, at a directory
holding an input and at a path inside an input; each must stop with exit 2 and a one-line
reason, and every input must hash the same before and after.
"""

from __future__ import annotations

import hashlib
import shutil
from collections.abc import Callable
from pathlib import Path

import pytest

from genbacklash_core import paper_example
from genbacklash_ros.bags.bagio import BagReader, BagWriter
from genbacklash_ros.bags.csvio import Series, write_series_csv
from genbacklash_ros.bags.output_marker import OUTPUT_MARKER
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, main
from genbacklash_ros.cli.paths import COMMAND_PATHS, OutputPathError, remove_own_output
from genbacklash_ros.node.messages import Float64

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE1_BAG = ROOT / "bags" / "example1"
TOPICS = ["--command", "/command", "--encoder", "/encoder"]


def tree_hash(path: Path) -> str:
    """One hash of a file, or of every file (names and bytes) below a directory."""
    digest = hashlib.sha256()
    if path.is_file():
        digest.update(path.read_bytes())
        return digest.hexdigest()
    for item in sorted(path.rglob("*")):
        digest.update(str(item.relative_to(path)).encode())
        if item.is_file():
            digest.update(item.read_bytes())
    return digest.hexdigest()


@pytest.fixture
def inputs(tmp_path: Path) -> dict[str, Path]:
    """A bag directory, a bare .mcap in a directory, a CSV, a params file, a start file."""
    bag = tmp_path / "recording"
    shutil.copytree(EXAMPLE1_BAG, bag)
    folder = tmp_path / "folder"
    folder.mkdir()
    mcap = folder / "run.mcap"
    shutil.copy(next(bag.glob("*.mcap")), mcap)
    data = paper_example(1).generate(0)
    csv = tmp_path / "csvdir" / "data.csv"
    csv.parent.mkdir()
    write_series_csv(csv, Series(u=data.u, y=data.y))
    params = tmp_path / "params.yaml"
    params.write_text("backlash_identifier:\n  ros__parameters:\n    degree: 1\n")
    return {"bag": bag, "mcap": mcap, "csv": csv, "params": params}


def _relations(target: Path) -> list[tuple[str, Path]]:
    """An output that is the input, contains it, and lies inside it."""
    return [("is", target), ("contains", target.parent), ("lies inside", target / "sub" / "out")]


# each case: a name, the input key, and how to build the command line given (input, output)
CASES: list[tuple[str, str, Callable[[Path, Path], list[str]]]] = [
    ("replay -o", "bag", lambda i, o: ["replay", str(i), *TOPICS, "-o", str(o), "--overwrite"]),
    ("replay -o mcap", "mcap", lambda i, o: ["replay", str(i), *TOPICS, "-o", str(o)]),
    (
        "replay --report",
        "bag",
        lambda i, o: ["replay", str(i), *TOPICS, "-o", str(i.parent / "new"), "--report", str(o)],
    ),
    ("identify --plot", "csv", lambda i, o: ["identify", str(i), "--plot", str(o)]),
    ("identify bag --plot", "bag", lambda i, o: ["identify", str(i), *TOPICS, "--plot", str(o)]),
    ("diagnose --report", "csv", lambda i, o: ["diagnose", str(i), "--report", str(o)]),
    (
        "replay --params-file",
        "params",
        lambda i, o: [
            "replay",
            str(EXAMPLE1_BAG),
            *TOPICS,
            "--params-file",
            str(i),
            "-o",
            str(o),
            "--overwrite",
        ],
    ),
    ("fleet --db", "bag", lambda i, o: ["fleet", str(i), *TOPICS, "--db", str(o)]),
]


@pytest.mark.parametrize(("name", "key", "build"), CASES, ids=[c[0] for c in CASES])
def test_no_output_may_be_contain_or_lie_inside_an_input(
    name: str,
    key: str,
    build: Callable[[Path, Path], list[str]],
    inputs: dict[str, Path],
    capsys: pytest.CaptureFixture[str],
) -> None:
    target = inputs[key]
    before = {k: tree_hash(p) for k, p in inputs.items()}
    for relation, output in _relations(target):
        if name == "fleet --db" and relation != "lies inside":
            continue  # a database file cannot be a directory; the directory cases are above
        code = main(build(target, output))
        err = capsys.readouterr().err
        assert code == EXIT_BAD_INPUT, (name, relation, err)
        assert f"{relation} the input" in err, (name, relation, err)
        assert "Traceback" not in err and err.count("\n") == 1, err
        assert not (target.parent / "new").exists()  # stopped before any work
    assert {k: tree_hash(p) for k, p in inputs.items()} == before


def test_the_issue_reproduction_keeps_the_recording(
    inputs: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    """`replay victim ... -o victim --overwrite` deleted the recording (issue 22, Why 1)."""
    victim = inputs["bag"]
    before = tree_hash(victim)
    code = main(["replay", str(victim), *TOPICS, "-o", str(victim), "--overwrite"])
    assert code == EXIT_BAD_INPUT
    assert "is the input BAG" in capsys.readouterr().err
    assert tree_hash(victim) == before
    with BagReader(victim) as reader:
        assert "/encoder" in reader.topics


def test_a_link_to_the_input_is_the_input(
    inputs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    link = tmp_path / "alias"
    link.symlink_to(inputs["bag"])
    before = tree_hash(inputs["bag"])
    assert main(["replay", str(inputs["bag"]), *TOPICS, "-o", str(link), "--overwrite"]) == 2
    assert "is the input BAG" in capsys.readouterr().err
    assert tree_hash(inputs["bag"]) == before


def test_overwrite_replaces_only_what_genbacklash_wrote(
    inputs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "out"
    args = ["replay", str(EXAMPLE1_BAG), *TOPICS, "-o", str(out), "--no-progress"]
    assert main(args) == EXIT_OK
    assert (out / OUTPUT_MARKER).is_file()
    assert main(args) == EXIT_BAD_INPUT
    assert "exists already" in capsys.readouterr().err
    assert main([*args, "--overwrite"]) == EXIT_OK
    capsys.readouterr()

    # a recording (no marker), a marked bag with a file of the user's, a plain file, a
    # directory of notes: none is removed
    mine = out / "notes.txt"
    mine.write_text("mine")
    plain = tmp_path / "plain.txt"
    plain.write_text("keep")
    notes = tmp_path / "notes"
    notes.mkdir()
    (notes / "a.txt").write_text("keep")
    for target in (inputs["bag"], out, plain, notes):
        before = tree_hash(target)
        code = main(["replay", str(EXAMPLE1_BAG), *TOPICS, "-o", str(target), "--overwrite"])
        err = capsys.readouterr().err
        assert code == EXIT_BAD_INPUT, err
        assert "not removing it" in err and err.count("\n") == 1, err
        assert tree_hash(target) == before


def test_remove_own_output_refuses_anything_else(tmp_path: Path) -> None:
    with BagWriter(tmp_path / "ours") as writer:
        writer.write("/x", 1, Float64(1.0))
    (tmp_path / "theirs").mkdir()
    (tmp_path / "theirs" / "metadata.yaml").write_text("x")
    with pytest.raises(OutputPathError, match=r"has no genbacklash-output\.json"):
        remove_own_output(tmp_path / "theirs")
    (tmp_path / "ours" / "sub").mkdir()
    with pytest.raises(OutputPathError, match="holds sub/"):
        remove_own_output(tmp_path / "ours")
    (tmp_path / "ours" / "sub").rmdir()
    remove_own_output(tmp_path / "ours")
    assert not (tmp_path / "ours").exists()


@pytest.mark.parametrize(
    ("option", "make"),
    [
        ("--report", lambda p: p.write_text("a file")),
        ("--report", lambda p: None),  # under /proc, see below
    ],
)
def test_unwritable_outputs_stop_before_the_work(
    option: str,
    make: Callable[[Path], None],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    report = tmp_path / "report"
    make(report)
    if not report.exists():
        report = Path("/proc/genbacklash-no-such-place/report")
    out = tmp_path / "out"
    code = main(["replay", str(EXAMPLE1_BAG), *TOPICS, "-o", str(out), option, str(report)])
    err = capsys.readouterr().err
    assert code == EXIT_BAD_INPUT
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert not out.exists()  # nothing replayed


@pytest.mark.parametrize(
    "argv",
    [
        ["identify", "{csv}", "--plot", "{file}"],
        ["diagnose", "{csv}", "--report", "{file}"],
        ["demo", "--out", "{file}"],
        ["simulate", "--example", "1", "-o", "{dir}"],
        ["simulate", "--example", "1", "--bag", "{file}"],
        ["excite", "--range", "0", "1", "--v-max", "1", "--a-max", "5", "-o", "{file}/x.csv"],
        ["fleet-report", "{db}", "--gap-limit", "0.1", "-o", "{file}"],
        ["export", "{csv}", "-o", "{file}/table", "--range", "-1", "1"],
        ["readings", "{bag}", "--command", "/command", "--encoder", "/encoder", "-o", "{file}/r"],
        ["identify", "{csv}", "--checkpoint", "{file}/start.json"],
    ],
)
def test_every_writing_command_checks_its_outputs_first(
    argv: list[str],
    inputs: dict[str, Path],
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    afile = tmp_path / "afile"
    afile.write_text("keep")
    adir = tmp_path / "adir"
    adir.mkdir()
    db = tmp_path / "fleet.db"
    db.write_text("not a database")
    words = [
        w.format(csv=inputs["csv"], file=afile, dir=adir, db=db, bag=inputs["bag"]) for w in argv
    ]
    code = main(words)
    err = capsys.readouterr().err
    assert code == EXIT_BAD_INPUT, err
    assert "Traceback" not in err and err.count("\n") == 1, err
    assert afile.read_text() == "keep"


def test_every_command_with_paths_is_in_the_table() -> None:
    """A new writing command must be added to COMMAND_PATHS (checked by its options)."""
    from genbacklash_ros.cli.main import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    path_words = {"-o", "--output", "--out", "--report", "--plot", "--bag", "--db"}
    for name, command in sub.choices.items():  # type: ignore[union-attr]
        options = {s for a in command._actions for s in a.option_strings}
        if options & path_words:
            assert name in COMMAND_PATHS, name
