"""Fleet kill -9: `genbacklash fleet` killed half-way, twice, then run again to the end.

    python bench/fleet_kill.py [--quick] [--seeds 0 1 2] [--drivetrains N] [--days D] [--seconds S]

Inputs: per seed a synthetic fleet (``genbacklash_ros.fleet.synthetic``): N drivetrains x D
days of S-second bags of a drivetrain in normal operation (moves and dwells, 100 Hz held
commands, a 1 kHz encoder quantised to 4096 counts/rev losing 2 % of its readings), one bag
cut short (corrupt) and one without motion; default 4 x 6 x 20 s = 24 bags.

Each seed: the `genbacklash fleet` command line with its defaults (a local Dask cluster of 2
worker processes, batch identify with standard deviations and diagnose, a new SQLite
database) is started as a subprocess and sent SIGKILL once a third of the bags have rows,
started again and killed at two thirds, then run to its end, then run once more. Counted
from the database: rows that were lost (a bag without its row), duplicated (a bag with two
rows for the same settings), changed (a row stored before a kill that differs after it),
the corrupt bag's row, and the rows the last, idempotent run added.
"""

from __future__ import annotations

import argparse
import os
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import command_line, machine_description, md_table, write_section

from genbacklash_ros.fleet.synthetic import SyntheticFleetSpec, write_synthetic_fleet

Row = tuple[int, str, str, str, str, str]


def _rows(db: Path) -> list[Row]:
    """(id, bag path, joint, settings key, status, processed at) of every row, by id."""
    if not db.exists():
        return []
    try:
        with sqlite3.connect(db, timeout=10) as conn:
            query = (
                "select id, bag_path, joint, settings_key, status, processed_at "
                "from bag_results order by id"
            )
            return list(conn.execute(query))
    except sqlite3.OperationalError:  # the table is not there yet
        return []


def _run_until(command: list[str], db: Path, rows: int | None) -> tuple[int, float]:
    """Run ``command`` in its own process group; with ``rows``, SIGKILL its main process as
    soon as the database holds that many rows (then its Dask workers, left behind). The
    return code and the wall time."""
    started = time.perf_counter()
    child = subprocess.Popen(
        command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    try:
        if rows is None:
            child.wait(timeout=1800)
        else:
            while len(_rows(db)) < rows and child.poll() is None:
                time.sleep(0.02)
            if child.poll() is None:
                os.kill(child.pid, signal.SIGKILL)  # kill -9 of the fleet run itself
            child.wait(timeout=60)
    finally:
        try:  # the worker processes it started, orphaned by the kill
            os.killpg(child.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
    return child.returncode, time.perf_counter() - started


def one_seed(seed: int, spec: SyntheticFleetSpec, root: Path) -> dict[str, object]:
    fleet = write_synthetic_fleet(root / f"archive-{seed}", spec)
    db = root / f"fleet-{seed}.db"
    command = [
        str(Path(sys.executable).parent / "genbacklash"),
        *("fleet", str(root / f"archive-{seed}"), "--db", str(db), "--no-progress"),
    ]
    n = len(fleet.bags)
    kills = []
    for fraction in (1 / 3, 2 / 3):
        before = len(_rows(db))
        code, seconds = _run_until(command, db, max(before + 1, round(fraction * n)))
        kept = _rows(db)
        kills.append((code, len(kept), seconds, kept))
        print(f"seed {seed}: killed ({code}) at {len(kept)}/{n} rows", file=sys.stderr)
    code, seconds = _run_until(command, db, None)
    final = _rows(db)
    code_again, _ = _run_until(command, db, None)
    again = _rows(db)
    bags = {b.relpath for b in fleet.bags}
    keys = [(r[1], r[2], r[3]) for r in final]
    stored = {r[0]: r for r in final}
    changed = sum(
        1 for _, _, _, kept in kills for r in kept if stored.get(r[0]) != r
    )  # a row stored before a kill, not the same after
    corrupt = next(b.relpath for b in fleet.bags if b.kind == "corrupt")
    return {
        "seed": seed,
        "bags": n,
        "kills": [(k[0], k[1]) for k in kills],
        "final_code": code,
        "final_seconds": seconds,
        "rows": len(final),
        "lost": len(bags - {r[1] for r in final}),
        "duplicated": len(keys) - len(set(keys)),
        "changed": changed,
        "corrupt_status": [r[4] for r in final if r[1] == corrupt],
        "again_code": code_again,
        "again_added": len(again) - len(final),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--drivetrains", type=int, default=4)
    parser.add_argument("--days", type=int, default=6)
    parser.add_argument("--seconds", type=float, default=20.0)
    parser.add_argument("--quick", action="store_true", help="one seed, 3 x 4 bags of 10 s")
    args = parser.parse_args()
    if args.quick:
        args.seeds, args.drivetrains, args.days, args.seconds = [0], 3, 4, 10.0
    machine = machine_description()
    started = time.perf_counter()
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            spec = SyntheticFleetSpec(
                drivetrains=args.drivetrains,
                days=args.days,
                seconds=args.seconds,
                corrupt=1,
                no_motion=1,
                seed=seed,
            )
            results.append(one_seed(seed, spec, Path(tmp)))
    total = time.perf_counter() - started
    table = md_table(
        [
            "seed",
            "bags",
            "rows at the kills (return code)",
            "rows at the end",
            "lost",
            "duplicated",
            "changed after a kill",
            "corrupt bag's row",
            "rows the re-run added",
        ],
        [
            [
                str(r["seed"]),
                str(r["bags"]),
                ", ".join(f"{rows} ({code})" for code, rows in r["kills"]),  # type: ignore[attr-defined]
                str(r["rows"]),
                str(r["lost"]),
                str(r["duplicated"]),
                str(r["changed"]),
                ", ".join(r["corrupt_status"]),  # type: ignore[arg-type]
                str(r["again_added"]),
            ]
            for r in results
        ],
    )
    clean = all(
        r["lost"] == r["duplicated"] == r["changed"] == r["again_added"] == 0
        and r["corrupt_status"] == ["unreadable"]
        and r["final_code"] == r["again_code"] == 0
        and all(code == -signal.SIGKILL for code, _ in r["kills"])  # type: ignore[attr-defined]
        for r in results
    )
    verdict = "met" if clean else "NOT met"
    text = f"""## Fleet kill -9 (issue 13)

`{command_line()}`. Machine: {machine}. Run time {total:.0f} s.

Per seed, a synthetic fleet of {args.drivetrains} drivetrains x {args.days} days of
{args.seconds:g}-second bags of a drivetrain in normal operation (moves and dwells, 100 Hz
held commands, a 1 kHz encoder quantised to 4096 counts/rev losing 2 % of its readings), one
bag cut short and one without motion. `genbacklash fleet` with its defaults (local Dask
cluster of 2 worker processes, identify with standard deviations, diagnose, SQLite) is
killed with SIGKILL once a third of the bags have rows, started again and killed at two
thirds, run to its end, then run once more.

{table}

Target - corrupt bags isolated, 0 lost or duplicated rows after a kill -9 and a re-run:
**{verdict}** (rows kept across the kills unchanged; the last run added none).
"""
    write_section("fleet_kill", text)
    print(text)


if __name__ == "__main__":
    main()
