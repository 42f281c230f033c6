"""The recursive identifier's batch start (genbacklash_core.online.restart)."""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core import Structure, paper_example
from genbacklash_core.online.memory import BinnedRows
from genbacklash_core.online.restart import (
    MAX_REJECTIONS,
    backlash_start,
    cascade_start,
    rejected,
)
from genbacklash_core.online.rows import row_width
from genbacklash_core.online.settings import RecursiveSettings
from genbacklash_core.online.stream import RowStream


def test_backlash_start_on_a_memory_finds_the_model_and_its_sense() -> None:
    ex = paper_example(2)  # negative slopes: the sense is detected
    data = ex.generate(seed=0, n_samples=1500)
    structure = Structure(3)
    stream = RowStream(structure, 100)
    b = np.zeros(data.u.size, dtype=bool)
    rows, at = stream.take(structure, None, data.u, data.y, b, 1e-4, 0)
    memory = BinnedRows(6, 16, 1000, 30)
    memory.insert(rows, at)
    start = backlash_start(structure, False, memory, RecursiveSettings(), (-2.0, 2.0))
    assert not isinstance(start, str)
    assert start.structure.sign == -1.0 and start.memory is memory and start.lags is None
    p = start.structure.from_theta(start.solution.theta)
    assert np.max(np.abs(p - ex.model.parameters())) < 0.05


def test_cascade_start_refills_its_memory_from_the_window() -> None:
    ex = paper_example(3)
    data = ex.generate(seed=0)
    structure = Structure(3, 2, 2)
    memory = BinnedRows(row_width(structure), 16, 1000, 30)
    window = (data.u, data.y, np.zeros(data.u.size, dtype=bool))
    start = cascade_start(structure, True, window, 100, memory, RecursiveSettings(), (-1.0, 1.0))
    assert not isinstance(start, str)
    assert len(memory) > 0 and memory.rows()[1][0] >= 100  # stamped from sample `first` on
    assert start.lags is not None
    p = structure.from_theta(start.solution.theta)
    assert np.max(np.abs(p - ex.model.parameters())) < 0.05


def test_a_start_without_data_says_why() -> None:
    memory = BinnedRows(6, 16, 1000, 30)
    found = backlash_start(Structure(3), True, memory, RecursiveSettings(), (-1.0, 1.0))
    assert isinstance(found, str) and found


def test_rejection_of_a_restart_that_fits_worse_than_before() -> None:
    assert rejected(1.0, before=math.nan, ratio=5.0, attempt=0) is None  # not a restart
    assert rejected(2.0, before=0.1, ratio=5.0, attempt=0) is None  # within 5x in RMS
    assert rejected(3.0, before=0.1, ratio=5.0, attempt=0) is not None
    assert rejected(3.0, before=0.1, ratio=5.0, attempt=MAX_REJECTIONS) is None
