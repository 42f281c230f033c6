"""BLAS on one thread while a replay runs, restored after the last user (shared with the node)."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy  # noqa: F401  (loads OpenBLAS for threadpoolctl to find)
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

import genbacklash_ros.bags.replay as replay_module
from genbacklash_ros import blas_threads as shared
from genbacklash_ros.bags.replay import replay
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, JOINT, write_example_bag
from genbacklash_ros.blas_threads import one_blas_thread


def _blas_threads() -> set[int]:
    return {int(i["num_threads"]) for i in threadpool_info() if i["user_api"] == "blas"}


@pytest.fixture(scope="module")
def example_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("bags") / "ex1"
    write_example_bag(bag, 1, seed=2, n_samples=1500)
    return bag


def _replay(bag: Path, out: Path) -> str:
    result = replay(bag, out, command_topic=COMMAND_TOPIC, encoder_topic=ENCODER_TOPIC, joint=JOINT)
    return result.error


def test_overlapping_users_restore_the_threads_only_at_the_last() -> None:
    with threadpool_limits(2, "blas"):  # a known starting point, whatever the machine has
        assert _blas_threads() == {2}
        first, second = one_blas_thread(), one_blas_thread()
        first.__enter__()
        assert _blas_threads() == {1}
        second.__enter__()
        first.__exit__(None, None, None)  # not in the order entered (two fleet threads)
        assert _blas_threads() == {1}
        second.__exit__(None, None, None)
        assert _blas_threads() == {2}
    assert shared._users == 0


def test_a_replay_runs_on_one_blas_thread_and_gives_it_back(
    example_bag: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: list[set[int]] = []

    @contextmanager
    def watching() -> Iterator[None]:
        with one_blas_thread():
            seen.append(_blas_threads())
            yield

    monkeypatch.setattr(replay_module, "one_blas_thread", watching)
    with threadpool_limits(2, "blas"):
        assert _replay(example_bag, tmp_path / "out") == ""
        assert _blas_threads() == {2}
    assert seen == [{1}]


def test_replays_in_threads_share_the_limit(example_bag: Path, tmp_path: Path) -> None:
    errors: list[str] = []

    def run(k: int) -> None:
        errors.append(_replay(example_bag, tmp_path / f"out{k}"))

    with threadpool_limits(2, "blas"):
        threads = [threading.Thread(target=run, args=(k,)) for k in range(3)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert _blas_threads() == {2}
    assert errors == ["", "", ""]
    assert shared._users == 0
