"""The results table: round trip of every column, idempotent writes, clear errors."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.fleet.database import TABLE, ResultStore
from genbacklash_ros.fleet.job import BagResult


def _full_result() -> BagResult:
    return BagResult(
        bag_hash="f" * 64,
        joint="elbow",
        settings_key="k" * 64,
        robot="robot-1",
        bag_path="robot-1/elbow/2024-03-05",
        status="ok",
        reason="converged",
        recorded_ns=1_709_596_800_000_000_000,
        time_source="name",
        command_index=2,
        model="backlash",
        degree=1,
        c_left=0.05,
        c_left_std=1e-4,
        c_right=0.06,
        c_right_std=2e-4,
        gap=0.11,
        gap_std=2.2e-4,
        parameters={"m_left_1": 1.0, "c_left": 0.05, "m_right_1": 1.0, "c_right": 0.06},
        parameter_std={"m_left_1": 1e-3, "c_left": 1e-4, "m_right_1": 1e-3, "c_right": 2e-4},
        estimate={"model": "backlash", "backlash": {"m_left": [1.0], "c_left": 0.05}},
        nrmse=0.001,
        iterations=5,
        converged=True,
        n_samples=9800,
        duration_s=10.0,
        diagnose_effects="curved_branches",
        diagnose_gap_initial=0.02,
        diagnose_gap_final=0.001,
        diagnosis={"steps": [{"effect": "curved_branches"}], "gap_initial": 0.02},
        replay_gap=0.1101,
        replay_gap_std=3e-5,
        replay_state="converged",
        replay={"state": "converged", "u_max": math.inf},
        settings={"params": {"u_min": -math.inf}},
        software_version="9.9.9",
        compute_s=1.5,
    )


def test_round_trip_of_every_column(tmp_path: Path) -> None:
    result = _full_result()
    with ResultStore(tmp_path / "fleet.db") as store:
        assert store.add([result], archive="/data") == 1
        (row,) = store.results()
    stored = row._mapping
    expected = result.to_row()
    for name, value in expected.items():
        assert stored[name] == value, name
    assert expected["replay"]["u_max"] == "inf"  # non-finite JSON values as strings
    assert stored["archive"] == "/data"
    assert stored["recorded_at"] == "2024-03-05T00:00:00Z"
    assert set(stored.keys()) == {c.name for c in TABLE.columns}


def test_add_is_idempotent_and_keeps_the_first_row(tmp_path: Path) -> None:
    db = tmp_path / "fleet.db"
    first = _full_result()
    again = dataclasses.replace(first, gap=0.5)
    other_joint = dataclasses.replace(first, joint="wrist")
    with ResultStore(db) as store:
        assert store.add([first]) == 1
        assert store.add([again, other_joint]) == 1
    with ResultStore(f"sqlite:///{db}") as store:  # a URL works as well as a path
        rows = store.results()
        assert [(r.joint, r.gap) for r in rows] == [("elbow", 0.11), ("wrist", 0.11)]
        assert store.done_keys() == {("f" * 64, j, "k" * 64) for j in ("elbow", "wrist")}
        assert [r.joint for r in store.results(statuses=["no_motion"])] == []


def test_errors_are_one_line_and_say_what_to_do(tmp_path: Path) -> None:
    with pytest.raises(GenBacklashError, match="run 'genbacklash fleet' first"):
        ResultStore(tmp_path / "none.db", create=False)
    with pytest.raises(GenBacklashError, match="is not a directory"):
        ResultStore(tmp_path / "missing" / "fleet.db")
    with pytest.raises(GenBacklashError, match="cannot use the database"):
        ResultStore("nosuchdialect://x/y")
    (tmp_path / "other.db").write_bytes(b"")
    with pytest.raises(GenBacklashError, match="has no bag_results table"):
        ResultStore(tmp_path / "other.db", create=False)
    with pytest.raises(GenBacklashError, match="status must be one of"):
        dataclasses.replace(_full_result(), status="great")
