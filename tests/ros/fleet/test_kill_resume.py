"""A fleet run killed with SIGKILL half-way resumes without loss or duplicates (for real: a
subprocess, kill -9 once rows are in, the same command again).

The runs skip the diagnosis (``--no-diagnose``): what is tested is the database across a kill,
not the analysis, and without it a bag takes ~0.1 s instead of ~0.8 s. The archive has 18
bags so that well over a second of work remains when the kill lands after the third row.
"""

from __future__ import annotations

import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

from genbacklash_ros.cli.main import main
from genbacklash_ros.fleet.synthetic import SyntheticFleetSpec, write_synthetic_fleet


def _rows(db: Path) -> list[tuple[int, str, str, str]]:
    if not db.exists():
        return []
    try:
        with sqlite3.connect(db, timeout=5) as conn:
            query = "select id, bag_path, status, processed_at from bag_results order by id"
            return list(conn.execute(query))
    except sqlite3.OperationalError:  # the table is not there yet
        return []


def test_kill_9_then_rerun(tmp_path: Path) -> None:
    spec = SyntheticFleetSpec(drivetrains=3, days=6, seconds=4.0, corrupt=1, no_motion=0, seed=3)
    fleet = write_synthetic_fleet(tmp_path / "archive", spec)
    db = tmp_path / "fleet.db"
    command = [
        *(sys.executable, "-m", "genbacklash_ros.cli.main", "fleet", str(tmp_path / "archive")),
        *("--db", str(db), "--threads", "--workers", "1", "--no-progress", "--no-diagnose"),
    ]
    child = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 120
        while len(_rows(db)) < 3 and child.poll() is None and time.monotonic() < deadline:
            time.sleep(0.02)
        os.kill(child.pid, signal.SIGKILL)
    finally:
        child.wait(timeout=30)
    assert child.returncode == -signal.SIGKILL
    before = _rows(db)
    assert 3 <= len(before) < len(fleet.bags), "the kill did not land half-way"

    assert main(command[3:]) == 0  # the same command: only the missing bags
    after = _rows(db)
    assert after[: len(before)] == before  # what was stored is kept as it was
    assert sorted(r[1] for r in after) == sorted(b.relpath for b in fleet.bags)  # once each
    corrupt = next(b.relpath for b in fleet.bags if b.kind == "corrupt")
    with sqlite3.connect(db) as conn:  # its readable part used, and flagged
        flags = list(
            conn.execute("select truncated from bag_results where bag_path = ?", (corrupt,))
        )
    assert flags == [(1,)]
    assert main(command[3:]) == 0 and _rows(db) == after  # idempotent
    assert main([*command[3:], "--max-nrmse", "0.05"]) == 0  # other settings: a row per bag more
    assert len(_rows(db)) == 2 * len(fleet.bags)
