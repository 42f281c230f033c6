"""The sample rule at the ROS edge (issue 12, item 2): a regression row is formed only from
samples consecutive on the encoder's clock, in the node and in batch identify/diagnose."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import GeneralBacklash, identify_backlash, paper_example
from genbacklash_core.samples import sample_breaks
from genbacklash_ros.bags.bagio import read_aligned
from genbacklash_ros.bags.csvio import Series, read_series_csv, write_series_csv
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, JOINT, write_example_bag
from genbacklash_ros.cli.main import EXIT_OK, main
from genbacklash_ros.node.sample_rule import (
    EncoderPeriod,
    keep_breaks,
    link_breaks,
    record_period,
    time_breaks,
)
from tests.ros.bags.test_bagio import copy_without

MS = 1_000_000
T0 = 1_700_000_000 * 1_000_000_000


# --------------------------------------------------------------------------- the functions


def test_link_breaks_is_the_core_rule_linked_to_the_previous_sample() -> None:
    t = T0 + np.array([1, 2, 3, 5, 6, 7, 10]) * MS
    assert np.array_equal(link_breaks(t, MS), sample_breaks(t - T0, MS))
    assert link_breaks(t, MS, previous_ns=T0).tolist()[0] is False
    assert link_breaks(t, MS, previous_ns=T0 - MS).tolist()[0] is True  # one lost before
    assert link_breaks(t, MS, previous_ns=T0 + 5 * MS).tolist()[0] is True  # a jump back
    marks = np.zeros(7, dtype=bool)
    marks[1] = True
    assert np.flatnonzero(link_breaks(t, MS, marks=marks)).tolist() == [0, 1, 3, 6]
    assert link_breaks(t, None, previous_ns=T0).all()  # no period: nothing vouched for
    assert link_breaks(np.zeros(0, dtype=np.int64), MS).size == 0


def test_keep_breaks_breaks_after_every_sample_taken_out() -> None:
    breaks = np.array([True, False, False, False, False, False])
    keep = np.array([False, True, True, False, True, True])
    out, tail = keep_breaks(breaks, keep)
    assert out.tolist() == [True, False, True, False] and not tail
    out, tail = keep_breaks(breaks, np.array([True, True, True, True, True, False]))
    assert not out[1:].any() and tail
    out, tail = keep_breaks(breaks, np.zeros(6, dtype=bool))
    assert out.size == 0 and tail


def test_encoder_period_is_a_running_median() -> None:
    period = EncoderPeriod(window=5)
    assert period.value is None
    for step in (MS, MS, 2 * MS, 0, -MS, MS + 1000, 3 * MS):  # non-positive ones ignored
        period.add(step)
    assert period.value == MS + 1000  # median of the last five positive steps
    for _ in range(3):
        period.add(2 * MS)
    assert period.value == 2 * MS  # it follows a new rate
    period.reset()
    assert period.value is None


@settings(max_examples=200, deadline=None, derandomize=True, database=None)
@given(
    steps=st.lists(st.integers(-5, 3 * MS), max_size=40),
    window=st.integers(1, 12),
    big=st.booleans(),
)
def test_encoder_period_is_numpys_median(steps: list[int], window: int, big: bool) -> None:
    """The running median is numpy's, to the bit: the middle step, or the mean of the two
    middle ones as float64 (stamps of 2**62 ns too)."""
    period = EncoderPeriod(window=window)
    kept: list[int] = []
    for step in steps:
        step = step + 2**62 if big and step > 0 else step
        period.add(step)
        if step > 0:
            kept = [*kept, step][-window:]
        expected = float(np.median(np.array(kept, dtype=np.int64))) if kept else None
        assert period.value == expected


def test_record_period_and_time_breaks_in_any_unit() -> None:
    seconds = np.array([0.0, 0.001, 0.002, 0.004, 0.005, 0.0061])
    assert record_period(seconds) == pytest.approx(0.001)
    assert time_breaks(seconds).tolist() == [True, False, False, True, False, False]  # type: ignore[union-attr]
    ns = T0 + np.round(seconds * 1e9).astype(np.int64)
    assert time_breaks(ns).tolist() == time_breaks(seconds).tolist()  # type: ignore[union-attr]
    assert record_period(ns) == MS
    assert time_breaks([1.0]) is None and time_breaks([2.0, 2.0, 2.0]) is None
    with_nan = time_breaks([0.0, 1.0, np.nan, 3.0, 4.0])
    assert with_nan is not None and with_nan.tolist() == [True, False, True, True, False]


def test_csv_with_t_carries_breaks(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    u, y = rng.normal(size=20), rng.normal(size=20)
    t = np.delete(np.arange(21) * 1e-3, 7)  # row 7 lost
    write_series_csv(tmp_path / "t.csv", Series(u, y, t))
    series = read_series_csv(tmp_path / "t.csv")
    assert series.breaks is not None and np.flatnonzero(series.breaks).tolist() == [0, 7]
    write_series_csv(tmp_path / "plain.csv", Series(u, y))
    assert read_series_csv(tmp_path / "plain.csv").breaks is None


# --------------------------------------------------------------------------- batch on bags

TRUTH = paper_example(1).backlash


@pytest.fixture(scope="module")
def lossy_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Example 1 (3000 samples, SNR 25) as a bag with 30% of the encoder messages lost."""
    root = tmp_path_factory.mktemp("lossy")
    write_example_bag(root / "full", 1, seed=0, n_samples=3000, snr=25)
    rng = np.random.default_rng(12)
    lost = set(np.flatnonzero(rng.random(3000) < 0.3).tolist())
    copy_without(root / "full", root / "bag", ENCODER_TOPIC, lost)
    return root / "bag"


BAG_OPTIONS = ["--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC, "--joint", JOINT]


def test_identify_on_a_lossy_bag_is_unbiased(
    lossy_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["identify", str(lossy_bag), *BAG_OPTIONS, "--degree", "3", "--json"]) == EXIT_OK
    result = json.loads(capsys.readouterr().out)
    b = result["backlash"]
    estimate = np.array([*b["m_left"], b["c_left"], *b["m_right"], b["c_right"]])
    assert np.max(np.abs(estimate - TRUTH.parameters())) < 0.02
    # the same samples paired across the lost readings: both gaps read too small
    s = read_aligned(lossy_bag, COMMAND_TOPIC, ENCODER_TOPIC, joint=JOINT)
    assert 0.25 < np.mean(s.breaks) < 0.35
    paired = identify_backlash(s.u, s.y, 3).model
    assert isinstance(paired, GeneralBacklash)
    assert paired.c_left < TRUTH.c_left - 0.05 and paired.c_right < TRUTH.c_right - 0.05


def test_diagnose_on_a_lossy_bag_is_unbiased(
    lossy_bag: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["diagnose", str(lossy_bag), *BAG_OPTIONS, "--start", "degree=3", "--json"]
    assert main(args) == EXIT_OK
    result = json.loads(capsys.readouterr().out)
    b = result["model"]["backlash"]
    assert abs(b["c_left"] - TRUTH.c_left) < 0.02
    assert abs(b["c_right"] - TRUTH.c_right) < 0.02
