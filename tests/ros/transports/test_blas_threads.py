"""One BLAS thread while the node runs (:mod:`genbacklash_ros.blas_threads`): the
limit holds inside the block and the previous one comes back after it, and both transports
run their node inside it (``rclpy_node.main``; ``run_node`` with ``--transport dds``)."""

from __future__ import annotations

import argparse
import importlib
from typing import Any

import numpy  # noqa: F401  (loads numpy's BLAS, which threadpoolctl then sees)
import pytest
from threadpoolctl import threadpool_info, threadpool_limits

from genbacklash_ros.blas_threads import one_blas_thread
from genbacklash_ros.cli import node as cli_node

from ._ros2 import rclpy_missing


def blas_threads() -> set[int]:
    """The thread counts of the BLAS libraries loaded in this process."""
    return {int(p["num_threads"]) for p in threadpool_info() if p["user_api"] == "blas"}


def test_numpy_blas_is_seen() -> None:
    # without a BLAS that threadpoolctl sees, the tests below would compare empty sets
    assert blas_threads()


def test_one_thread_inside_and_the_previous_limit_after() -> None:
    with threadpool_limits(limits=2, user_api="blas"):
        assert blas_threads() == {2}
        with one_blas_thread() as limited:
            assert limited
            assert blas_threads() == {1}
        assert blas_threads() == {2}


def test_one_thread_after_an_exception_is_undone() -> None:
    with threadpool_limits(limits=2, user_api="blas"):
        with pytest.raises(RuntimeError, match="inside"), one_blas_thread():
            raise RuntimeError("inside")
        assert blas_threads() == {2}


def test_the_dds_node_runs_with_one_blas_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[set[int]] = []

    def fake_run_dds(args: Any, params: Any, stop: Any) -> int:
        seen.append(blas_threads())
        return 0

    monkeypatch.setattr(cli_node, "_run_dds", fake_run_dds)
    monkeypatch.setattr(cli_node, "choose_transport", lambda requested: "dds")
    args = cli_node._configure(argparse.ArgumentParser()).parse_args(["--transport", "dds"])
    with threadpool_limits(limits=2, user_api="blas"):
        assert cli_node.run_node(args) == 0
        assert blas_threads() == {2}
    assert seen == [{1}]


@pytest.mark.skipif(bool(rclpy_missing()), reason=rclpy_missing() or "-")
def test_the_rclpy_node_runs_with_one_blas_thread(monkeypatch: pytest.MonkeyPatch) -> None:
    rclpy_node = importlib.import_module("genbacklash_ros.transports.rclpy_node")
    seen: list[set[int]] = []

    def fake_run(argv: list[str], stop: Any) -> int:
        seen.append(blas_threads())
        return 0

    monkeypatch.setattr(rclpy_node, "_run", fake_run)
    with threadpool_limits(limits=2, user_api="blas"):
        assert rclpy_node.main(["backlash_identifier"]) == 0
        assert blas_threads() == {2}
    assert seen == [{1}]
