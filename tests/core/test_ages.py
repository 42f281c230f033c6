"""The age of the recursive identifier's information, per block (genbacklash_core.online.ages)."""

from __future__ import annotations

import numpy as np

from genbacklash_core.online.ages import RowAges


def test_idle_counts_from_the_newest_row_age_from_the_branch_left_longest() -> None:
    ages = RowAges(cascade=False)
    ages.restart(100)
    ages.note(np.array([120, 130]), np.array([True, True]), np.array([False, False]))
    assert ages.idle(200) == 70  # the left branch's newest row, at 130
    assert ages.age(200) == 100  # the right branch: nothing since the restart at 100


def test_every_row_informs_the_cascade_linear_block() -> None:
    ages = RowAges(cascade=True)
    ages.note(np.array([7]), np.array([False]), np.array([False]))  # neither branch
    assert ages.idle(10) == 3 and ages.age(10) == 10
    ages.note(np.array([], dtype=np.intp), np.array([], dtype=bool), np.array([], dtype=bool))
    assert ages.idle(10) == 3
