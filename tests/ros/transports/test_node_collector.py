"""Both transports run their node with the collector's pauses cut
(:func:`genbacklash_ros.gc_pauses.few_collections`): what exists once the node is built
frozen, the young generation collected seldom; the collector as it was after the node ends."""

from __future__ import annotations

import argparse
import gc
import importlib
from typing import Any

import pytest

from genbacklash_ros.cli import node as cli_node
from genbacklash_ros.gc_pauses import YOUNG
from genbacklash_ros.transports.stop_signals import StopSignals

from ._ros2 import rclpy_missing


def collector() -> tuple[int, int]:
    """The young generation's threshold and the number of frozen objects."""
    return gc.get_threshold()[0], gc.get_freeze_count()


def test_the_dds_node_spins_with_few_collections(monkeypatch: pytest.MonkeyPatch) -> None:
    dds_node = pytest.importorskip(
        "genbacklash_ros.transports.dds_node", reason="cyclonedds is not installed"
    )
    seen: list[tuple[int, int]] = []

    class Spy(dds_node.DdsNode):  # type: ignore[misc,name-defined]
        def spin(self, duration_s: float | None = None) -> Any:
            seen.append(collector())
            return super().spin(0.0)

    monkeypatch.setattr(dds_node, "DdsNode", Spy)
    monkeypatch.setattr(cli_node, "choose_transport", lambda requested: "dds")
    before = gc.get_threshold()
    args = cli_node._configure(argparse.ArgumentParser()).parse_args(
        ["--transport", "dds", "--domain-id", "7"]
    )
    assert cli_node.run_node(args) == 0
    assert len(seen) == 1 and seen[0][0] == YOUNG and seen[0][1] > 0
    assert gc.get_threshold() == before and gc.get_freeze_count() == 0


@pytest.mark.skipif(bool(rclpy_missing()), reason=rclpy_missing() or "-")
def test_the_rclpy_node_loops_with_few_collections(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Any
) -> None:
    rclpy_node = importlib.import_module("genbacklash_ros.transports.rclpy_node")
    stop = StopSignals()
    seen: list[tuple[int, int]] = []

    def run_once(self: Any, timeout_s: float = 0.0) -> int:
        seen.append(collector())
        stop.request()
        return 0

    monkeypatch.setattr(rclpy_node.WaitLoop, "run_once", run_once)
    monkeypatch.chdir(tmp_path)  # (the node's checkpoint, if any, is written here)
    before = gc.get_threshold()
    assert rclpy_node.main(["backlash_identifier"], stop=stop) == 0
    assert len(seen) == 1 and seen[0][0] == YOUNG and seen[0][1] > 0
    assert gc.get_threshold() == before and gc.get_freeze_count() == 0
