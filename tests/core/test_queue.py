"""The recursive identifier's queue of samples between events (genbacklash_core.online.queue)."""

from __future__ import annotations

import numpy as np

from genbacklash_core.online.queue import SampleQueue


def test_stretches_end_at_the_next_event_and_a_flush_hands_them_over_in_order() -> None:
    queue = SampleQueue()
    u = np.arange(10.0)
    b = np.zeros(10, dtype=bool)
    b[4] = True
    count = {"taken": 0, "due": 4}  # read again by the room after each stretch
    flushed = []
    for n in queue.take(u, 2.0 * u, b, lambda: count["due"] - count["taken"]):
        count["taken"] += n
        if count["taken"] >= count["due"]:
            piece = queue.flush(count["taken"])
            assert piece is not None
            flushed.append(piece)
            count["due"] += 4
    taken = count["taken"]
    assert [p[3] for p in flushed] == [0, 4]  # the index of each piece's first sample
    assert [p[0].tolist() for p in flushed] == [[0.0, 1.0, 2.0, 3.0], [4.0, 5.0, 6.0, 7.0]]
    assert flushed[1][2].tolist() == [True, False, False, False]
    assert queue.queued == 2 and queue.events == 2
    rest = queue.flush(taken)
    assert rest is not None and rest[0].tolist() == [8.0, 9.0] and rest[3] == 8
    assert queue.flush(taken) is None and queue.events == 3


def test_a_room_of_zero_still_takes_one_sample_at_a_time() -> None:
    queue = SampleQueue()
    u = np.ones(3)
    assert list(queue.take(u, u, np.zeros(3, dtype=bool), lambda: 0)) == [1, 1, 1]
    assert not queue.moved()  # the input rests
