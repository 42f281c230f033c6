"""A truncated bag's readable part is used and flagged (issue 22, deliverable 8).

Bags are cut by truncating their MCAP file, as a recorder killed mid-write leaves them; the
fleet analyses what can be read (the same messages a replay keeps), stores the flag, and
fleet-report says it in text, JSON and on the page. An older database without the new
columns is extended by ``fleet`` and read as it is by ``fleet-report``.
"""

from __future__ import annotations

import hashlib
import json
import shutil
import sqlite3
from pathlib import Path

import pytest

from genbacklash_ros.bags.bagio import BagError, BagReader, read_aligned
from genbacklash_ros.bags.replay import replay
from genbacklash_ros.cli.main import main
from genbacklash_ros.fleet.database import ADDED_COLUMNS, TABLE, ResultStore

TOPICS = ("/command", "/encoder")
SECONDS = 10.0


def _cut(path: Path, fraction: float) -> None:
    """Truncate the (one) MCAP file of a bag to ``fraction`` of its size."""
    file = path if path.suffix == ".mcap" else next(path.glob("*.mcap"))
    size = file.stat().st_size
    with file.open("r+b") as handle:
        handle.truncate(int(size * fraction))


@pytest.fixture(scope="module")
def archive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """robot-01: a whole bag, one cut (a rosbag2 directory) and one cut bare .mcap."""
    root = tmp_path_factory.mktemp("cut") / "archive"
    made = tmp_path_factory.mktemp("made")
    days = ("2024-03-01T08-00-00", "2024-03-02T08-00-00", "2024-03-03T08-00-00")
    for seed, day in enumerate(days):
        bag = made / day
        simulate = ["simulate", "--scenario", "operation", "--bag", str(bag)]
        assert main([*simulate, "--duration", str(SECONDS), "--seed", str(seed)]) == 0
    joint_dir = root / "robot-01" / "drive_joint"
    joint_dir.mkdir(parents=True)
    shutil.copytree(made / days[0], joint_dir / days[0])
    shutil.copytree(made / days[1], joint_dir / days[1])
    _cut(joint_dir / days[1], 0.55)
    shutil.copy(next((made / days[2]).glob("*.mcap")), joint_dir / f"{days[2]}.mcap")
    _cut(joint_dir / f"{days[2]}.mcap", 0.5)
    return root


@pytest.fixture(scope="module")
def db(archive: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("db") / "fleet.db"
    args = ["fleet", str(archive), "--db", str(path), "--threads", "--workers", "1"]
    assert main([*args, "--no-progress", "--no-diagnose"]) == 0
    return path


def test_the_readable_part_is_what_replay_keeps(archive: Path, db: Path, tmp_path: Path) -> None:
    with ResultStore(db) as store:
        rows = {Path(r.bag_path).name: r for r in store.results()}
    whole, cut, bare = (rows[name] for name in sorted(rows))
    assert whole.truncated is False and whole.status == "ok" and whole.recorded_s is None
    for row in (cut, bare):
        path = archive / row.bag_path
        with pytest.raises(BagError, match="truncated"):  # as before: the whole bag fails
            read_aligned(path, *TOPICS, joint="drive_joint")
        readable = read_aligned(path, *TOPICS, joint="drive_joint", keep_readable=True)
        assert "truncated" in readable.damage
        assert row.truncated is True and row.status == "ok", row.reason
        assert row.n_samples == readable.u.size > 2000
        assert row.gap is not None and row.gap == pytest.approx(whole.gap, rel=0.2)
        # replay keeps the same encoder readings of the cut bag
        output = tmp_path / row.bag_path.replace("/", "_")
        command, encoder = TOPICS
        result = replay(
            path, output, command_topic=command, encoder_topic=encoder, joint="drive_joint"
        )
        assert result.error and "truncated" in result.error
        with BagReader(output) as out:
            kept = out.topics["/encoder"].count
        assert kept == readable.u.size + readable.skipped
    assert cut.recorded_s == pytest.approx(SECONDS, abs=0.01)  # metadata.yaml survives the cut
    assert cut.reason.startswith(f"truncated: read {cut.duration_s:.1f} of 10.0 s (")
    assert 4.0 < cut.duration_s < 7.0
    assert bare.recorded_s is None  # a bare .mcap's metadata was at its cut end
    assert bare.reason.startswith(f"truncated: read {bare.duration_s:.1f} s (the rest is lost)")


def test_fleet_report_flags_it_in_text_json_and_page(
    db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "report"
    assert main(["fleet-report", str(db), "--play-limit", "0.2", "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert "truncated bags (their readable part analysed):" in text
    assert "2024-03-02T08-00-00: truncated: read" in text and "of 10.0 s (ok)" in text
    assert "2024-03-03T08-00-00.mcap: truncated: read" in text and "(the rest is lost)" in text
    summary = json.loads((out / "summary.json").read_text())
    (item,) = summary["drivetrains"]
    flags = [bag["flag"] for bag in item["truncated_bags"]]
    assert len(flags) == 2 and all(f.startswith("truncated: read ") for f in flags)
    assert item["points"]["truncated"] == [False, True, True]
    page = (out / "index.html").read_text()
    assert "Truncated bags" in page and flags[0] in page and flags[1] in page
    assert main(["fleet-report", str(db), "--play-limit", "0.2", "-o", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    assert printed["drivetrains"][0]["truncated_bags"] == item["truncated_bags"]


def _old_database(path: Path) -> None:
    """The table as genbacklash wrote it before the added columns, with one row."""
    columns = [c for c in TABLE.columns if c.name not in ADDED_COLUMNS]
    with sqlite3.connect(path) as conn:
        body = ", ".join(
            f"{c.name} {'INTEGER PRIMARY KEY' if c.primary_key else ''}" for c in columns
        )
        conn.execute(f"CREATE TABLE bag_results ({body})")
        conn.execute(
            "INSERT INTO bag_results (bag_hash, joint, settings_key, robot, bag_path, status, "
            "reason, recorded_ns, gap, gap_std, software_version, processed_at) VALUES "
            "('h', 'j', 'k', 'r', 'r/2024-03-01', 'ok', 'fine', 1709280000000000000, 0.1, "
            "0.001, '0.1', '2024-03-01T09:00:00Z')"
        )


def test_an_older_database_is_read_as_it_is_and_extended_by_fleet(tmp_path: Path) -> None:
    old = tmp_path / "old.db"
    _old_database(old)
    digest = hashlib.sha256(old.read_bytes()).hexdigest()
    with ResultStore(old, create=False) as store:  # fleet-report: reads, changes nothing
        (row,) = store.results()
    assert row.gap == 0.1 and row.truncated is None and row.recorded_s is None
    assert hashlib.sha256(old.read_bytes()).hexdigest() == digest
    with ResultStore(old) as store:  # fleet: adds the columns, the old row reads NULL
        (row,) = store.results()
        assert row.truncated is None and row.status == "ok"
    with sqlite3.connect(old) as conn:
        names = [r[1] for r in conn.execute("PRAGMA table_info(bag_results)")]
    assert names[-len(ADDED_COLUMNS) :] == list(ADDED_COLUMNS)
    with ResultStore(old) as store:  # a second open adds nothing
        assert len(store.results()) == 1
