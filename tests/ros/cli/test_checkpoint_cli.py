"""identify and replay --checkpoint write a start the node takes (issue 22, deliverable 6).

The file is written by the node's own checkpoint writer; a pipeline started with
``checkpoint_file`` pointing at it warm-starts from it (its estimate before any data is the
file's), and one of another structure refuses it with the node's message.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import paper_example
from genbacklash_ros.bags.csvio import Series, write_series_csv
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_OK, main
from genbacklash_ros.node.checkpoint import load_checkpoint, warm_start
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE1_BAG = ROOT / "bags" / "example1"
TOPICS = ["--command", "/command", "--encoder", "/encoder"]


@pytest.fixture
def csv(tmp_path: Path) -> Path:
    data = paper_example(1).generate(0)
    path = tmp_path / "data.csv"
    write_series_csv(path, Series(u=data.u, y=data.y))
    return path


def _assert_node_starts_from(path: Path, **structure: object) -> None:
    saved = load_checkpoint(path).estimate
    pipeline = BacklashPipeline(NodeParameters(checkpoint_file=str(path), **structure))  # type: ignore[arg-type]
    assert "warm start from checkpoint" in pipeline.warm_start_note
    assert pipeline.using_checkpoint
    before = pipeline.estimate  # no data yet
    assert before.available
    np.testing.assert_array_equal(before.parameters, saved.parameters)
    assert before.structure == saved.structure
    assert before.model == saved.model


def test_identify_writes_the_start_the_node_takes(
    csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    start = tmp_path / "start" / "checkpoint.json"
    assert main(["identify", str(csv), "--json", "--checkpoint", str(start)]) == EXIT_OK
    out, err = capsys.readouterr()
    identified = json.loads(out)
    assert f"checkpoint_file={start} model=backlash degree=3" in err
    saved = load_checkpoint(start).estimate
    backlash = identified["backlash"]
    expected = [*backlash["m_left"], backlash["c_left"], *backlash["m_right"], backlash["c_right"]]
    np.testing.assert_array_equal(saved.parameters, expected)
    assert saved.state.value == "converged"
    assert np.all(np.isfinite(saved.covariance)) and np.all(saved.std() > 0)
    # with a covariance the node's identifier is seeded: it continues from the estimate
    start_of_node = warm_start(NodeParameters(checkpoint_file=str(start)))
    assert start_of_node.seeded and not start_of_node.problem, start_of_node.note
    _assert_node_starts_from(start)


def test_replay_writes_the_start_the_node_takes(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    start = tmp_path / "replayed.json"
    argv = ["replay", str(EXAMPLE1_BAG), *TOPICS, "-o", str(tmp_path / "out"), "--no-progress"]
    assert main([*argv, "--json", "--checkpoint", str(start)]) == EXIT_OK
    out, err = capsys.readouterr()
    final = json.loads(out)
    assert "model=backlash degree=3" in err
    saved = load_checkpoint(start)
    assert saved.time_ns > 0  # the data time of the final estimate
    assert saved.estimate.state.value == final["state"]
    np.testing.assert_array_equal(
        saved.estimate.parameters, [final["parameters"][n] for n in saved.estimate.names]
    )
    _assert_node_starts_from(start)


def test_a_cascade_start_names_its_orders(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = paper_example(3).generate(0)
    csv = tmp_path / "cascade.csv"
    write_series_csv(csv, Series(u=data.u, y=data.y))
    start = tmp_path / "cascade.json"
    code = main(["identify", str(csv), "--model", "cascade", "--checkpoint", str(start)])
    assert code == EXIT_OK
    assert "model=cascade degree=3 na=2 nb=2" in capsys.readouterr().err
    _assert_node_starts_from(start, model="cascade", na=2, nb=2)


def test_a_start_of_another_structure_is_refused(
    csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    start = tmp_path / "degree1.json"
    assert main(["identify", str(csv), "--degree", "1", "--checkpoint", str(start)]) in (0, 3)
    capsys.readouterr()
    pipeline = BacklashPipeline(NodeParameters(checkpoint_file=str(start)))  # degree 3
    note = pipeline.warm_start_note
    assert f"checkpoint {start} not used: the checkpoint holds degree 1, na 0, nb 0; " in note
    assert "the parameters ask for degree 3, na 0, nb 0; starting cold" in note
    assert not pipeline.estimate.available
    assert not pipeline.using_checkpoint


def test_checkpoint_paths_are_checked_before_the_work(
    csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = csv.read_bytes()
    for argv in (
        ["identify", str(csv), "--checkpoint", str(csv)],
        ["identify", str(csv), "--checkpoint", str(tmp_path)],
        ["replay", str(EXAMPLE1_BAG), *TOPICS, "-o", str(tmp_path / "o"), "--checkpoint",
         str(EXAMPLE1_BAG / "metadata.yaml")],
    ):  # fmt: skip
        assert main(argv) == EXIT_BAD_INPUT
        err = capsys.readouterr().err
        assert "--checkpoint" in err and err.count("\n") == 1 and "Traceback" not in err, err
    assert csv.read_bytes() == before
    assert not (tmp_path / "o").exists()


# ------------------------------------------------------------- the record's tracking baseline


def test_identify_and_replay_store_the_records_tracking_without_compensation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # a bag of commands and readings alone: the drivetrain got the commands as they are
    bag, topics = ROOT / "bags" / "drivetrain", [*TOPICS, "--joint", "drive_joint"]
    identified, replayed = tmp_path / "identified.json", tmp_path / "replayed.json"
    main(["identify", str(bag), *topics, "--checkpoint", str(identified)])
    out = tmp_path / "out"
    argv = ["replay", str(bag), *topics, "-o", str(out), "--no-progress"]
    assert main([*argv, "--checkpoint", str(replayed)]) == EXIT_OK
    assert "as the measured-tracking baseline" in capsys.readouterr().err
    first, second = load_checkpoint(identified).baseline, load_checkpoint(replayed).baseline
    assert first is not None and second is not None
    assert 9.0 < first.seconds < 10.0  # the 10 s record's readings
    # one measurement, the judge's, on the same messages
    assert first.rms == pytest.approx(second.rms, rel=1e-9)
    assert first.seconds == pytest.approx(second.seconds, rel=1e-9)
    # the replay's output holds the node's compensated commands: its record is not counted
    again = tmp_path / "again.json"
    main(["identify", str(out), *topics, "--checkpoint", str(again)])
    assert load_checkpoint(again).baseline is None
    assert "no tracking baseline stored" in capsys.readouterr().err


def test_a_csv_cannot_tell_and_stores_no_baseline(
    csv: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    start = tmp_path / "start.json"
    assert main(["identify", str(csv), "--checkpoint", str(start)]) == EXIT_OK
    assert load_checkpoint(start).baseline is None
    assert "no tracking baseline stored" in capsys.readouterr().err
