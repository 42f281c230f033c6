"""SIGINT and SIGTERM at any moment of a fed node end it cleanly: exit 0, no traceback (issue 24).

``genbacklash node`` runs as its own process while a feeder process publishes a command and a
reading at 1 kHz (``_shutdown.py``, ``feeder.py``); once the feeder sees it subscribed it gets,
at a seeded-random moment, a SIGINT, a SIGTERM, two SIGINTs or a SIGTERM and a SIGINT 0-500 ms
apart. Before the fix a second SIGINT 5-250 ms after the first ended the process by SIGINT (the
handlers were restored before the interpreter's shutdown), and a SIGINT landing in rclpy's message
take ended in ``RuntimeError: Unable to convert call argument '0' to Python object`` and exit 1.
``bench/shutdown.py`` runs 50 trials of each kind. The rclpy node also runs with
``thread_priority`` (identification in a child process): the child must end with it.
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from pathlib import Path

import pytest

from ._ros2 import domain_id, rclpy_missing
from ._shutdown import KINDS, Feeder, trial, write_params

pytestmark = pytest.mark.skipif(bool(rclpy_missing()), reason=rclpy_missing() or "-")

# trials of each kind per transport: ~2 s each (start-up, feed, finish)
TRIALS = {"rclpy": 3, "dds": 2, "rclpy-priority": 1}


@pytest.fixture(scope="module")
def feeder() -> Iterator[Feeder]:
    fed = Feeder(domain_id())
    try:
        yield fed
    finally:
        fed.close()


@pytest.mark.parametrize("variant", ["rclpy", "dds", "rclpy-priority"])
def test_signals_at_random_moments_end_the_fed_node_cleanly(
    feeder: Feeder, variant: str, tmp_path: Path
) -> None:
    transport = variant.split("-")[0]
    if transport == "dds":
        pytest.importorskip("cyclonedds", reason="the dds transport needs cyclonedds (dds extra)")
    rng = random.Random(f"shutdown-{variant}")
    params = write_params(tmp_path, thread_priority=10 if variant.endswith("priority") else 0)
    plan = [
        (kind, rng.uniform(0.0, 1.5), rng.uniform(0.0, 0.5))
        for _ in range(TRIALS[variant])
        for kind in KINDS
    ]
    unclean = []
    for kind, delay, gap in plan:
        outcome = trial(feeder, transport, params, kind, delay, gap)
        # the identify process exists with thread_priority only (and must end: clean)
        assert outcome.children == (1 if variant.endswith("priority") else 0), outcome
        if not outcome.clean:
            unclean.append(outcome.describe())
    assert not unclean, f"{len(unclean)} of {len(plan)} unclean:\n" + "\n".join(unclean)
