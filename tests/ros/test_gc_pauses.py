"""The collector policy of the node and of replays (genbacklash_ros.gc_pauses)."""

from __future__ import annotations

import gc

import pytest

from genbacklash_ros.gc_pauses import YOUNG, few_collections


def test_the_collector_comes_back_as_it_was_found() -> None:
    """The collector's thresholds and freeze come back when the last user ends, also when
    users overlap (fleet threads run several replays) and when one raises."""
    before = gc.get_threshold()
    assert gc.get_freeze_count() == 0
    with few_collections():
        assert gc.get_threshold()[0] == YOUNG and gc.get_freeze_count() > 0
        with pytest.raises(RuntimeError), few_collections():  # a second one, which fails
            raise RuntimeError("damaged")
        assert gc.get_threshold()[0] == YOUNG  # the first still runs
        assert gc.get_freeze_count() > 0
    assert gc.get_threshold() == before
    assert gc.get_freeze_count() == 0


def test_a_full_collection_inside_does_not_scan_what_was_there_before() -> None:
    """What existed on entry is frozen: a full collection inside finds its cycles no more
    (they are collected again after the last user leaves), and cycles made inside are still
    collected."""

    class Node:
        def __init__(self) -> None:
            self.me = self

    gc.collect()
    Node()  # a cycle that exists on entry (unreachable, not yet collected)
    with few_collections():
        assert gc.collect() == 0  # frozen with everything else
        Node()  # made inside
        assert gc.collect() > 0
    assert gc.collect() > 0  # thawed: the first one goes now
