"""Run a fleet archive on Dask: inspect every bag, analyse what the database lacks, store rows.

:func:`run_fleet` submits :func:`~genbacklash_ros.fleet.job.inspect_bag` for every bag the
archive holds to a ``dask.distributed`` cluster, and as each plan comes back it submits
:func:`~genbacklash_ros.fleet.job.analyse_bag` for the joints whose ``(bag_hash, joint,
settings_key)`` is not in the database yet. The driver (this process) alone writes the
database, one transaction per bag as its result arrives, so:

* a re-run skips what is done (idempotent);
* a run killed at any moment loses at most the bags in flight, which the next run redoes;
  the unique key keeps a row from ever being stored twice;
* a bag that cannot be read is a row with its reason (the job never raises for a bad bag);
  a task lost to the cluster itself (a worker that died) is counted in
  :attr:`FleetRun.lost` and left for the next run.

The cluster: :func:`fleet_client` starts a ``LocalCluster`` on this machine (``workers``
processes of one thread each) unless ``scheduler`` gives the address of a running one
(``tcp://host:8786``), whose workers need genbacklash installed and the archive at the same
path.
"""

from __future__ import annotations

import dataclasses
import time
from collections import Counter
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from genbacklash_core import GenBacklashError
from genbacklash_ros.fleet.archive import discover
from genbacklash_ros.fleet.database import ResultStore
from genbacklash_ros.fleet.job import (
    BagPlan,
    BagResult,
    FleetSettings,
    analyse_bag,
    inspect_bag,
    truncation_note,
)

__all__ = ["FleetRun", "fleet_client", "run_fleet"]


@dataclass
class FleetRun:
    """What one run did.

    Attributes
    ----------
    bags : int
        Bags found in the archive.
    analysed : int
        Bags analysed in this run (their rows added).
    skipped : int
        Bags whose every joint was already in the database.
    rows : int
        Rows added.
    statuses : Counter
        Status -> rows added with it.
    lost : list of str
        Bags whose task the cluster lost (``relpath: reason``); a re-run retries them.
    seconds : float
        Wall-clock time of the run (cluster start excluded).
    truncated : list of str
        Rows of bags cut part-way, analysed on their readable part (``relpath: truncated:
        read X of Y s``).
    """

    bags: int = 0
    analysed: int = 0
    skipped: int = 0
    rows: int = 0
    statuses: Counter[str] = field(default_factory=Counter)
    lost: list[str] = field(default_factory=list)
    seconds: float = 0.0
    truncated: list[str] = field(default_factory=list)

    def summary(self) -> str:
        """One line for the terminal."""
        statuses = ", ".join(f"{n} {s}" for s, n in sorted(self.statuses.items())) or "none"
        rate = self.analysed / self.seconds * 60 if self.seconds > 0 else 0.0
        text = (
            f"{self.bags} bag{'' if self.bags == 1 else 's'}: {self.analysed} analysed "
            f"({rate:.1f} bags/min), "
            f"{self.skipped} already in the database; {self.rows} rows added ({statuses})"
        )
        if self.truncated:
            n = len(self.truncated)
            text += (
                f"; {n} row{'' if n == 1 else 's'} of truncated bags, from their readable "
                f"part: {'; '.join(self.truncated)}"
            )
        if self.lost:
            text += f"; {len(self.lost)} lost to the cluster (run again to retry)"
        return text


@contextmanager
def fleet_client(
    scheduler: str | None = None, *, workers: int = 1, processes: bool = True
) -> Iterator[Any]:
    """A ``dask.distributed.Client``: connected to ``scheduler``, else on a new
    ``LocalCluster`` of ``workers`` single-threaded workers (``processes=False``: threads
    in this process, which starts in a fraction of a second; for tests)."""
    import distributed

    dask: Any = distributed  # untyped library: called through Any
    if scheduler:
        try:
            client = dask.Client(scheduler, timeout="10s")
        except (OSError, TimeoutError) as err:
            raise GenBacklashError(
                f"cannot reach the Dask scheduler at {scheduler}: {err}; start one "
                "('dask scheduler') or drop --scheduler for a local cluster"
            ) from err
        try:
            yield client
        finally:
            client.close()
        return
    if workers < 1:
        raise GenBacklashError(f"--workers must be >= 1, got {workers}")
    cluster = dask.LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=processes,
        dashboard_address=":0",  # any free port: other clusters may run here
    )
    client = dask.Client(cluster)
    try:
        yield client
    finally:
        client.close()
        cluster.close()


def run_fleet(
    archive: str | Path,
    store: ResultStore,
    settings: FleetSettings,
    client: Any,
    *,
    progress: bool = False,
) -> FleetRun:
    """Analyse every bag of ``archive`` the database lacks (see the module notes).

    Parameters
    ----------
    archive : str or Path
        The root of the bag tree (:func:`~genbacklash_ros.fleet.archive.discover`).
    store : ResultStore
    settings : FleetSettings
    client : distributed.Client
        From :func:`fleet_client`.
    progress : bool
        Progress over the bags on stderr (:class:`~genbacklash_ros.progress.Progress`).
    """
    import distributed

    from genbacklash_ros.progress import Progress

    dask: Any = distributed

    started = time.perf_counter()
    bags = discover(archive)
    root = str(Path(archive).resolve())
    run = FleetRun(bags=len(bags))
    done = store.done_keys()
    # a bar on a terminal, else a plain line on stderr every few seconds (a fleet run
    # under cron or CI said nothing for minutes)
    bar = Progress("genbacklash fleet", total=len(bags), unit="bag", enabled=progress)
    kind: dict[Any, tuple[str, str]] = {}
    plans = client.map(inspect_bag, bags, settings=settings, pure=False)
    for future, bag in zip(plans, bags, strict=True):
        kind[future] = ("inspect", bag.relpath)
    queue = dask.as_completed(plans)
    try:
        for future in queue:
            what, relpath = kind.pop(future)
            if future.status != "finished":
                run.lost.append(f"{relpath}: {future.exception()!r}")
                bar.update(1)
                continue
            value = future.result()
            if what == "inspect":
                plan: BagPlan = value
                todo = [
                    (joint, index)
                    for joint, index in plan.joints
                    if (plan.bag_hash, joint, settings.key(joint, index)) not in done
                ]
                if plan.reason or todo:
                    plan = dataclasses.replace(plan, joints=tuple(todo))
                    job = client.submit(analyse_bag, plan, settings, pure=False)
                    kind[job] = ("analyse", relpath)
                    queue.add(job)
                else:
                    run.skipped += 1
                    bar.update(1)
                continue
            results: tuple[BagResult, ...] = value
            added = store.add(results, archive=root)
            for result in results:
                done.add((result.bag_hash, result.joint, result.settings_key))
                run.statuses[result.status] += 1
                if result.truncated:
                    note = truncation_note(result.duration_s, result.recorded_s)
                    run.truncated.append(f"{result.bag_path}: {note}")
            run.rows += added
            run.analysed += 1
            bar.update(1)
    finally:
        bar.close()
    run.seconds = time.perf_counter() - started
    return run
