"""The row memory (genbacklash_core.online.memory): information filed by branch and input region."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core.errors import GenBacklashError
from genbacklash_core.online.memory import RowMemory


def _moves(rng: np.random.Generator, lo: float, hi: float, n: int) -> np.ndarray:
    return rng.uniform(lo, hi, n)


def test_dwells_and_breaks_add_nothing() -> None:
    mem = RowMemory(capacity=100, bins=4)
    u = np.array([0.0, 0.0, 0.0, 0.5, 0.5, 0.2, 0.9])
    y = u.copy()
    breaks = np.array([True, False, False, False, False, False, True])
    assert mem.add_series(u, y, breaks) == 2  # 0 -> 0.5 and 0.5 -> 0.2; 0.2 -> 0.9 breaks
    u0, u1, _, _ = mem.rows()
    assert u0.tolist() == [0.0, 0.5] and u1.tolist() == [0.5, 0.2]


def test_new_rows_push_out_old_ones_only_in_their_own_region() -> None:
    """Forget only where newer data cover the same region."""
    rng = np.random.default_rng(0)
    mem = RowMemory(capacity=64, bins=4)  # 8 rows per bin
    u = _moves(rng, -1.0, 1.0, 2000)
    mem.add_series(u, np.zeros_like(u), np.zeros(u.size, dtype=bool))
    before = mem.coverage()
    assert before.share("left") == before.share("right") == 1.0
    old = set(mem.rows()[1].tolist())
    # thousands of new moves in the upper quarter only
    u2 = _moves(rng, 0.55, 1.0, 4000)
    mem.add_series(u2, np.ones_like(u2), np.zeros(u2.size, dtype=bool))
    _, u1, y0, _ = mem.rows()
    upper = u1 >= 0.5
    assert np.all(y0[upper] == 1.0)  # the upper region holds only new rows
    lower = u1[~upper]
    assert lower.size >= 3 * 2 * 8 - 2 and set(lower.tolist()) <= old  # the rest is kept
    assert len(mem) <= 2 * 4 * 8


def test_series_forms_one_row_per_pair() -> None:
    mem = RowMemory(capacity=40, bins=2)
    mem.add(np.array([0.0, 1.0]), np.array([1.0, 0.5]), np.array([0.1, 0.9]), np.array([0.9, 0.6]))
    u, y, breaks = mem.series()
    assert u.tolist() == [0.0, 1.0, 1.0, 0.5]
    assert y.tolist() == [0.1, 0.9, 0.9, 0.6]
    assert breaks.tolist() == [True, False, True, False]


def test_discard_and_coverage_gaps() -> None:
    mem = RowMemory(capacity=40, bins=4)
    u0 = np.array([0.0, 0.1, 0.9, 0.8])
    u1 = np.array([0.1, 0.2, 0.8, 0.7])
    mem.add(u0, u1, u0, u1)
    cover = mem.coverage()  # range [0.1, 0.8] in 4 regions: moves up in the first only
    assert cover.up.tolist() == [2, 0, 0, 0] and cover.down.tolist() == [0, 0, 0, 2]
    assert cover.share("right") == 0.25 and cover.share("left") == 0.25
    assert cover.empty_regions("left") == [(pytest.approx(0.1), pytest.approx(0.625))]
    assert mem.discard(np.array([True, False, False, False])) == 1
    assert len(mem) == 3


def test_bad_arguments() -> None:
    with pytest.raises(GenBacklashError, match="capacity"):
        RowMemory(1)
    with pytest.raises(GenBacklashError, match="bins"):
        RowMemory(10, bins=0)


def test_excitation_advice_names_what_is_missing_and_the_motion() -> None:
    from genbacklash_core.online.advice import coverage_of, excitation_advice

    up = np.linspace(0.0, 1.0, 101)
    down = up[::-1]
    # up only: the left branch (moves down) is missing
    cover = coverage_of(up[:-1], up[1:], 8, 100)
    assert excitation_advice(cover, moved=True) == (
        "the left branch is not covered yet: move the joint down"
    )
    # down only over the lower half: the right branch is missing, the left has holes above
    lower = down[50:]
    both = coverage_of(np.r_[up[:-1], lower[:-1]], np.r_[up[1:], lower[1:]], 8, 100)
    text = excitation_advice(both, moved=True)
    assert "the right branch" not in text
    assert text.startswith("the left branch has no data over [0.5")
    assert text.endswith("move down there")
    # everything covered: nothing to say, unless rows are still needed for the first fit
    full = coverage_of(np.r_[up[:-1], down[:-1]], np.r_[up[1:], down[1:]], 8, 100)
    assert excitation_advice(full, moved=True) == ""
    assert excitation_advice(full, moved=True, rows_needed=7).startswith("7 more moves")
    assert excitation_advice(full, moved=False).startswith("the input is constant")


@pytest.mark.parametrize("kind", ["windowed", "recursive"])
def test_identifiers_warming_up_say_which_motion_is_missing(kind: str) -> None:
    """A joint that has only moved one way is told to move the other way; once it has
    reversed across its range the advice goes."""
    from genbacklash_core import RecursiveIdentifier, WindowedIdentifier, paper_example

    model = paper_example(1).model
    ident = WindowedIdentifier(3) if kind == "windowed" else RecursiveIdentifier(3)
    u_up = np.linspace(-1.5, 1.5, 600)
    y_up = model.simulate(u_up)
    est = ident.update_many(u_up, y_up)
    assert est.state.value == "warming_up"
    assert "the left branch is not covered yet: move the joint down" in est.reason
    u = np.tile(np.r_[np.linspace(1.5, -1.5, 300), np.linspace(-1.5, 1.5, 300)], 4)
    est = ident.update_many(u, model.simulate(u, x0=float(y_up[-1])))
    assert "not covered" not in est.reason
    assert "no data over" not in est.reason
