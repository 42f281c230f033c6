"""A CSV and a bag of the same readings give the same answer (issue 23, deliverable 2).

``genbacklash readings`` writes a bag's readings (t in ns, the command held, the reading); the
CSV goes through the same row rules as the bag (``select_rows``: the servo's settling rule,
lost readings bridged), so ``identify`` and ``diagnose`` answer alike on both.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core.settling import settling_keep
from genbacklash_ros.bags.bagio import BagWriter, read_aligned
from genbacklash_ros.bags.csvio import read_series_csv, stamps_ns, write_readings_csv
from genbacklash_ros.cli.main import EXIT_NOT_CONVERGED, EXIT_OK, main
from genbacklash_ros.node.messages import Float64, JointState
from genbacklash_ros.node.sample_rule import select_rows

try:
    import mujoco  # noqa: F401

    HAVE_MUJOCO = True
except ImportError:
    HAVE_MUJOCO = False

TOPICS = ["--command", "/command", "--encoder", "/encoder", "--joint", "drive_joint"]


def _json(argv: list[str], capsys: pytest.CaptureFixture[str]) -> dict[str, object]:
    code = main(argv)
    out, err = capsys.readouterr()
    assert code in (EXIT_OK, EXIT_NOT_CONVERGED), err  # not converged: still the estimate
    return dict(json.loads(out))


def _close(a: object, b: object, path: str = "") -> None:
    """Equal JSON, numbers to 1e-12."""
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), path
        for key in a:
            _close(a[key], b[key], f"{path}.{key}")
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _close(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, rel=0, abs=1e-12), path
    else:
        assert a == b, path


def _bag_and_csv(
    bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], topics: list[str]
) -> Path:
    csv = tmp_path / "readings.csv"
    assert main(["readings", str(bag), *topics, "-o", str(csv)]) == EXIT_OK
    err = capsys.readouterr().err
    assert "take the same rows from the CSV as from the bag" in err, err
    return csv


@pytest.mark.skipif(not HAVE_MUJOCO, reason="needs mujoco (genbacklash[physics])")
@pytest.mark.parametrize("variant", ["near_ideal", "coasting"])
def test_a_physics_bag_and_its_csv_give_the_same_identify(
    variant: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "bag"
    simulate = ["simulate", "--physics", variant, "--bag", str(bag), "--duration", "12"]
    assert main([*simulate, "--seed", "1"]) == EXIT_OK
    capsys.readouterr()
    csv = _bag_and_csv(bag, tmp_path, capsys, TOPICS)
    # the settling rule takes readings out on this bag: the CSV must take the same ones
    every = read_aligned(bag, "/command", "/encoder", joint="drive_joint")
    assert not settling_keep(every.t, every.u, 5_000_000)[0].all()
    for model in ("backlash", "cascade"):
        from_bag = _json(["identify", str(bag), *TOPICS, "--json", "--model", model], capsys)
        from_csv = _json(["identify", str(csv), "--json", "--model", model], capsys)
        _close(from_bag, from_csv)
    # the rule's own setting reaches both
    bag_5 = _json(["identify", str(bag), *TOPICS, "--json", "--param", "settle_time=0.003"], capsys)
    csv_5 = _json(["identify", str(csv), "--json", "--param", "settle_time=0.003"], capsys)
    _close(bag_5, csv_5)


def test_the_operation_bag_and_its_csv_give_the_same_identify_and_diagnose(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    bag = tmp_path / "op"
    simulate = ["simulate", "--scenario", "operation", "--bag", str(bag), "--duration", "15"]
    assert main([*simulate, "--seed", "2", "--loss", "0.05"]) == EXIT_OK
    capsys.readouterr()
    topics = TOPICS
    csv = _bag_and_csv(bag, tmp_path, capsys, topics)
    _close(
        _json(["identify", str(bag), *topics, "--json"], capsys),
        _json(["identify", str(csv), "--json"], capsys),
    )
    bag_d = _json(["diagnose", str(bag), *topics, "--json"], capsys)
    csv_d = _json(["diagnose", str(csv), "--json"], capsys)
    _close(bag_d, csv_d)


def test_the_csv_applies_the_bags_rules_not_its_own(tmp_path: Path) -> None:
    """Readings with lost ones and slow commands: the CSV's rows are select_rows's, with the
    settling rule and bridging, and differ from the stamps' breaks alone."""
    rng = np.random.default_rng(4)
    n = 400
    t = np.arange(n, dtype=np.int64) * 1_000_000 + 1_700_000_000_000_000_000  # epoch ns
    u = np.repeat(np.cumsum(rng.choice([-0.01, 0.01], n // 10)), 10)
    y = rng.normal(size=n)
    kept = rng.random(n) > 0.05
    write_readings_csv(tmp_path / "r.csv", t[kept], u[kept], y[kept])
    change = np.r_[True, u[kept][1:] != u[kept][:-1]]
    rows = select_rows(
        t[kept], np.cumsum(change) - 1, u[kept][change], y[kept], bridge=True, settle_ns=4_000_000
    )
    series = read_series_csv(tmp_path / "r.csv", bridge=True, settle_ns=4_000_000)
    assert series.breaks is not None
    assert np.array_equal(series.u, rows.u) and np.array_equal(series.y, rows.y)
    assert np.array_equal(series.breaks, rows.breaks)
    assert rows.u.size < np.count_nonzero(kept)  # settling took readings out
    plain = read_series_csv(tmp_path / "r.csv")
    assert plain.u.size == np.count_nonzero(kept)  # no rule asked: every reading


def test_epoch_nanoseconds_are_read_exactly(tmp_path: Path) -> None:
    t = np.array([1_700_000_000_000_000_001, 1_700_000_000_001_000_003], dtype=np.int64)
    write_readings_csv(tmp_path / "r.csv", t, [0.1, 0.2], [0.3, 0.4])
    assert (tmp_path / "r.csv").read_text().splitlines()[1].startswith("1700000000000000001,")
    assert stamps_ns(t) is not None and np.array_equal(stamps_ns(t), t)  # type: ignore[arg-type]
    series = read_series_csv(tmp_path / "r.csv")
    assert series.u.tolist() == [0.1, 0.2] and series.y.tolist() == [0.3, 0.4]


def test_readings_says_when_the_csv_cannot_hold_the_bags_rows(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A rejected reading (NaN) breaks the chain in the bag; a CSV of readings cannot carry
    it, and the command says so rather than claim the same rows."""
    bag = tmp_path / "bag"
    with BagWriter(bag) as writer:
        writer.add_topic("/command", "std_msgs/msg/Float64")
        writer.add_topic("/encoder", "sensor_msgs/msg/JointState")
        for k in range(300):
            t = 1_000_000 * k
            if k % 10 == 0:
                writer.write("/command", t, Float64(data=0.1 * np.sin(k / 30)))
            y = float("nan") if k == 155 else 0.05 * np.sin((k - 3) / 30)
            state = JointState(name=("j",), position=(y,))
            writer.write("/encoder", t + 1, state)
    code = main(
        [
            "readings",
            str(bag),
            "--command",
            "/command",
            "--encoder",
            "/encoder",
            "-o",
            str(tmp_path / "r.csv"),
        ]
    )
    err = capsys.readouterr().err
    assert code == EXIT_OK, err
    assert "rows differ from the bag's" in err and "rejected readings" in err
