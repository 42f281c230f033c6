"""The spike screen on its own (genbacklash_ros.node.spike_screen); through the stream health
and with the rules' records in test_health.py."""

from __future__ import annotations

import dataclasses

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import Estimate, EstimatorState, GeneralBacklash
from genbacklash_core.structure import Structure
from genbacklash_ros.node.health_events import Drop
from genbacklash_ros.node.spike_screen import SCREEN_SAMPLES, SpikeScreen, exact_median
from tests.ros.node.test_health import _converged as converged
from tests.ros.node.test_health import _moving as moving  # (seed, n): times, u, y

MS = 1_000_000
SILENCE_NS = 100 * MS
MODEL = GeneralBacklash((1.0,), 0.05, (1.0,), 0.05)


def _converged(state: EstimatorState = EstimatorState.CONVERGED) -> Estimate:
    return dataclasses.replace(converged(MODEL), state=state)


def _warm(screen: SpikeScreen, times: np.ndarray, u: np.ndarray, y: np.ndarray) -> None:
    """Feed ``times[:640]`` in steps: the screen learns the scale and trusts the estimate."""
    est = _converged()
    for k in range(0, 640, SCREEN_SAMPLES):
        part = slice(k, k + SCREEN_SAMPLES)
        found = screen.screen(times[part], u[part], y[part], est, silence_ns=SILENCE_NS)
        assert found.keep is None and found.events == []


def test_an_isolated_spike_is_not_fed_and_counted() -> None:
    times, u, y = moving(1, 1280)
    y[900] += 0.05
    screen = SpikeScreen()
    assert screen.scale is None and not screen.trusted(_converged())  # no scale yet
    _warm(screen, times, u, y)
    assert screen.scale is not None and screen.trusted(_converged())
    found = screen.screen(times[640:], u[640:], y[640:], _converged(), silence_ns=SILENCE_NS)
    assert found.keep is not None and np.flatnonzero(~found.keep).tolist() == [900 - 640]
    assert [(e.key, e.count) for e in found.events if isinstance(e, Drop)] == [("encoder_spike", 1)]


def test_no_spike_while_the_model_does_not_fit_or_the_estimate_warms_up() -> None:
    times, u, y = moving(1, 1280)
    y[900] += 0.05
    screen = SpikeScreen()
    _warm(screen, times, u, y)
    screen.model_fits = False
    found = screen.screen(times[640:], u[640:], y[640:], _converged(), silence_ns=SILENCE_NS)
    assert found.keep is None and found.events == []
    # an identifier warming up again may not judge (until it has converged anew)
    assert not screen.trusted(_converged(EstimatorState.WARMING_UP))
    assert not screen.trusted(_converged(EstimatorState.CONVERGING))


def test_without_a_backlash_model_everything_is_fed() -> None:
    times, u, y = moving(1, 64)
    found = SpikeScreen().screen(times, u, y, Estimate.empty(Structure(3)), silence_ns=SILENCE_NS)
    assert found.keep is None and found.events == []


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False), min_size=1, max_size=40)
)
def test_exact_median_is_numpys_to_the_bit(values: list[float]) -> None:
    """The screen's and the rate window's median (one partition) is ``np.median``'s."""
    array = np.array(values)
    assert exact_median(array) == float(np.median(array))
    assert list(array) == values  # the input is not reordered
