"""The compensation guard (genbacklash_core.guard): its ratio predicts what compensation
cuts, and it fades compensation out where it would not help (issue 23, deliverable 3)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from genbacklash_core import (
    CompensationGuard,
    GenBacklashError,
    GeneralBacklash,
    GuardSettings,
    compensate,
    simulate_backlash,
)
from genbacklash_core.guard import CLEAR_FIT, free_run
from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    HiddenEffects,
    OperationSettings,
    drive,
    operation_commands,
)


def _scaled(model: GeneralBacklash, factor: float) -> GeneralBacklash:
    return GeneralBacklash(
        model.m_left, model.c_left * factor, model.m_right, model.c_right * factor
    )


def _run(values: np.ndarray, hidden: HiddenEffects | None, seed: int) -> tuple[np.ndarray, ...]:
    rng = np.random.default_rng(seed)
    cmd_t, t, u, _x, y, *_ = drive(
        rng,
        values,
        OPERATION_BACKLASH,
        command_rate=100.0,
        encoder_rate=1000.0,
        command_jitter_ns=0,
        stamp_jitter_ns=0.0,
        hidden=hidden,
    )
    return cmd_t, t, u, y


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize(
    ("hidden", "factor"),
    [
        (None, 1.0),
        (None, 1.6),
        (HiddenEffects(input_lag=0.003), 1.3),
        (HiddenEffects(load_lag=0.02), 1.0),
        (HiddenEffects(delay=0.01), 1.6),
    ],
)
def test_the_ratio_predicts_the_cut_of_compensation(
    seed: int, hidden: HiddenEffects | None, factor: float
) -> None:
    """On operation-shaped motion (moves, dwells, reversals, 100 Hz held commands, 1 kHz
    readings), judged on uncompensated data, ``1 - rho`` is the cut compensation with that
    model then gives in closed loop, within 8 points."""
    rng = np.random.default_rng([seed, 12])
    r, _ = operation_commands(rng, OperationSettings(duration=30.0))
    cmd_t, t, u, y = _run(r, hidden, seed)
    k = np.maximum(np.searchsorted(cmd_t, t, side="right") - 1, 0)
    off = float(np.sqrt(np.mean((y - r[k]) ** 2)))
    model = _scaled(OPERATION_BACKLASH, factor)
    verdict = CompensationGuard().update(u, y, np.zeros(y.size, dtype=bool), model)
    _, _, _, y_on = _run(compensate(model, r), hidden, seed)
    cut = 1.0 - float(np.sqrt(np.mean((y_on - r[k]) ** 2))) / off
    assert abs((1.0 - verdict.ratio) - cut) < 0.08, (verdict.ratio, cut)


def test_a_model_that_would_make_tracking_worse_is_switched_off() -> None:
    """Three times the play: compensating would overshoot every reversal."""
    u = 0.3 * np.sin(np.linspace(0.0, 60.0, 6000))
    true = GeneralBacklash.ideal(1.0, 0.04, 0.04)
    y = simulate_backlash(true, u)
    wrong = GeneralBacklash.ideal(1.0, 0.12, 0.12)
    guard = CompensationGuard()
    verdict = guard.update(u, y, np.zeros(u.size, dtype=bool), wrong)
    assert verdict.ratio > 1.5
    assert verdict.state == "off" and verdict.trust == 0.0
    assert "compensation off" in verdict.reason and "rad rms" in verdict.reason
    # off also tracks worse in closed loop: the guard was right
    on = simulate_backlash(true, compensate(wrong, u))
    assert np.sqrt(np.mean((on - u) ** 2)) > np.sqrt(np.mean((y - u) ** 2))


def test_evidence_moves_trust_from_one_to_the_judgement() -> None:
    u = 0.3 * np.sin(np.linspace(0.0, 60.0, 6000))
    y = simulate_backlash(GeneralBacklash.ideal(1.0, 0.04, 0.04), u)
    wrong = GeneralBacklash.ideal(1.0, 0.12, 0.12)
    guard = CompensationGuard(GuardSettings(min_samples=1000))
    assert guard.verdict.state == "judging" and guard.verdict.trust == 1.0
    trusts = []
    for start in range(0, 1536, 512):
        part = slice(start, start + 512)
        trusts.append(guard.update(u[part], y[part], np.zeros(512, dtype=bool), wrong).trust)
    # a new model is judged at once (512 of 1000 samples of evidence, fit 0); then the next
    # JUDGE_EVERY samples wait and are judged together
    assert trusts == pytest.approx([1 - 0.512, 1 - 0.512, 0.0])


def test_disabled_guard_keeps_compensation_but_still_judges() -> None:
    u = 0.3 * np.sin(np.linspace(0.0, 60.0, 6000))
    y = simulate_backlash(GeneralBacklash.ideal(1.0, 0.04, 0.04), u)
    guard = CompensationGuard(GuardSettings(enabled=False))
    verdict = guard.update(u, y, np.zeros(u.size, dtype=bool), GeneralBacklash.ideal(1, 0.2, 0.2))
    assert verdict.trust == 1.0 and verdict.state == "off"
    assert verdict.reason.startswith("guard disabled")
    assert guard.configure(GuardSettings()).trust == 0.0


def test_batches_equal_one_call_and_breaks_restart_the_chain() -> None:
    rng = np.random.default_rng(5)
    u = np.cumsum(rng.normal(0.0, 0.01, 3000))
    model = GeneralBacklash.ideal(1.0, 0.03, 0.05)
    y = simulate_backlash(model, u) + rng.normal(0.0, 1e-3, u.size)
    brk = np.zeros(u.size, dtype=bool)
    whole = CompensationGuard().update(u, y, brk, model)
    parts = CompensationGuard()
    for start in range(0, u.size, 128):
        parts.update(
            u[start : start + 128], y[start : start + 128], brk[start : start + 128], model
        )
    verdict = parts.flush()
    assert verdict.ratio == pytest.approx(whole.ratio, rel=1e-9)
    # a break re-anchors the model's output at the measured load: a jump of the load the
    # model cannot explain is not held against it after a break
    y2 = y.copy()
    y2[1500:] += 0.2
    broken = brk.copy()
    broken[1500] = True
    with_break = CompensationGuard().update(u, y2, broken, model)
    without = CompensationGuard().update(u, y2, brk, model)
    assert with_break.ratio < without.ratio


def test_no_model_and_empty_batches_change_nothing() -> None:
    guard = CompensationGuard()
    before = guard.verdict
    assert guard.update(np.zeros(0), np.zeros(0), np.zeros(0, dtype=bool), None) == before
    assert guard.update(np.ones(5), np.ones(5), np.zeros(5, dtype=bool), None) == before


@pytest.mark.parametrize(
    "kwargs",
    [{"window": 0}, {"min_samples": -1}, {"rho_full": 0.0}, {"rho_full": 0.9, "rho_off": 0.8}],
)
def test_settings_are_validated(kwargs: dict[str, float]) -> None:
    with pytest.raises(GenBacklashError):
        GuardSettings(**kwargs)  # type: ignore[arg-type]


@settings(max_examples=60, deadline=None, derandomize=True)
@given(
    c=st.floats(0.005, 0.2),
    factor=st.floats(0.2, 4.0),
    noise=st.floats(0.0, 0.01),
    seed=st.integers(0, 2**16),
)
def test_trust_stays_in_range_and_a_state_says_it(
    c: float, factor: float, noise: float, seed: int
) -> None:
    rng = np.random.default_rng(seed)
    u = np.cumsum(rng.normal(0.0, 0.02, 800))
    y = simulate_backlash(GeneralBacklash.ideal(1.0, c, c), u) + rng.normal(0.0, 1.0, 800) * noise
    verdict = CompensationGuard().update(
        u, y, np.zeros(u.size, dtype=bool), GeneralBacklash.ideal(1.0, c * factor, c * factor)
    )
    assert 0.0 <= verdict.trust <= 1.0
    assert verdict.state == {0.0: "off", 1.0: "on"}.get(verdict.trust, "faded")
    assert math.isfinite(verdict.model_rms) and verdict.samples == 800


def test_a_new_model_is_judged_at_once_on_the_samples_remembered() -> None:
    u = 0.3 * np.sin(np.linspace(0.0, 60.0, 6000))
    true = GeneralBacklash.ideal(1.0, 0.04, 0.04)
    y = simulate_backlash(true, u)
    guard = CompensationGuard()
    for start in range(0, 6000, 500):
        part = slice(start, start + 500)
        guard.update(u[part], y[part], np.zeros(500, dtype=bool), true)
    assert guard.verdict.state == "on"
    verdict = guard.adopt(GeneralBacklash.ideal(1.0, 0.12, 0.12))
    assert verdict.state == "off" and verdict.samples == 6000  # no wait for new evidence
    # after an "off", a model far below rho_full (CLEAR_FIT of it) is back at once too
    assert guard.adopt(true).state == "on"
    # history before the first model counts too
    fresh = CompensationGuard()
    fresh.update(u, y, np.zeros(u.size, dtype=bool), None)
    assert fresh.update(u[:10], y[:10], np.zeros(10, dtype=bool), true).samples == 6010


@pytest.mark.parametrize("decreasing", [False, True])
@pytest.mark.parametrize("x_prev", [None, 0.1])
def test_free_run_equals_a_simulation_per_stretch_between_breaks(
    decreasing: bool, x_prev: float | None
) -> None:
    """One play-operator scan over a batch with a break every few samples gives exactly what
    the guard computed before: one simulation per stretch, from the measured load clamped into
    the play (the first stretch from ``x_prev`` when the chain goes on)."""
    rng = np.random.default_rng(11)
    u = np.cumsum(rng.normal(0.0, 0.02, 3000))
    model = GeneralBacklash(
        m_left=(1.1, 0.05, -0.02), c_left=0.04, m_right=(0.9, 0.03, 0.01), c_right=0.06
    )
    if decreasing:
        model = GeneralBacklash(
            m_left=(-1.1, 0.05, -0.02), c_left=0.04, m_right=(-0.9, 0.03, 0.01), c_right=0.06
        )
    y = simulate_backlash(model, u) + rng.normal(0.0, 0.01, u.size)
    brk = rng.random(u.size) < 0.4
    brk[0] = False
    starts = [0, *(np.flatnonzero(brk[1:]) + 1).tolist()]
    ends = [*starts[1:], u.size]
    expected = np.empty(u.size)
    for start, stop in zip(starts, ends, strict=True):
        x0 = x_prev if start == 0 and x_prev is not None else None
        if x0 is None:
            lo, hi = sorted(model.branches_at(float(u[start])))
            x0 = min(max(float(y[start]), lo), hi)
        expected[start:stop] = simulate_backlash(model, u[start:stop], x0)
    got = free_run(model, u, y, brk, x_prev)
    np.testing.assert_array_equal(got, expected)


def test_free_run_refuses_branches_that_are_not_finite() -> None:
    model = GeneralBacklash(
        m_left=(1.0, 0.0, 1e300), c_left=0.1, m_right=(1.0, 0.0, 0.0), c_right=0.1
    )
    u = np.array([0.0, 1e200])
    with pytest.raises(GenBacklashError, match="not finite"):
        free_run(model, u, np.zeros(2), np.zeros(2, dtype=bool))


def test_the_window_weights_are_the_powers_computed_per_batch() -> None:
    """The cached powers (CompensationGuard._weights) give, bit for bit, the weights
    ``decay**(n-1-k)`` computed afresh for each batch, as the cache grows and when the
    window (so the decay) changes; and a guard's verdicts are those of the fresh ones."""
    guard = CompensationGuard(GuardSettings(window=500))
    for window in (500, 2000, 500):
        decay = math.exp(-1.0 / window)
        for n in (1, 2, 7, 16, 17, 1000, 333, 6001, 5, 12_345):
            fresh = decay ** np.arange(n - 1, -1, -1, dtype=np.float64)
            cached = guard._weights(decay, n)
            assert cached.flags.c_contiguous
            np.testing.assert_array_equal(cached, fresh)
            assert float(cached.sum()) == float(fresh.sum())

    class Fresh(CompensationGuard):
        def _weights(self, decay: float, n: int) -> np.ndarray:
            return decay ** np.arange(n - 1, -1, -1, dtype=np.float64)

    rng = np.random.default_rng(24)
    u = np.cumsum(rng.normal(0.0, 0.01, 9000))
    y = simulate_backlash(OPERATION_BACKLASH, u) + rng.normal(0.0, 1e-4, u.size)
    breaks = rng.random(u.size) < 0.01
    guards = [CompensationGuard(GuardSettings(window=700)), Fresh(GuardSettings(window=700))]
    for start in range(0, u.size, 1500):
        part = slice(start, start + 1500)
        model = _scaled(OPERATION_BACKLASH, 1.0 + start / 9000)  # a new model: judged anew
        verdicts = [g.update(u[part], y[part], breaks[part], model) for g in guards]
        assert verdicts[0] == verdicts[1]


def _band_case() -> tuple[np.ndarray, np.ndarray, GeneralBacklash, GeneralBacklash]:
    """A sine through a play of 0.08; a model whose error ratio lies in the fade band and one
    far off (three times the play)."""
    u = 0.3 * np.sin(np.linspace(0.0, 60.0, 6000))
    y = simulate_backlash(GeneralBacklash.ideal(1.0, 0.04, 0.04), u)
    return u, y, GeneralBacklash.ideal(1.0, 0.005, 0.005), GeneralBacklash.ideal(1.0, 0.12, 0.12)


def test_a_guard_never_off_fades_in_the_band() -> None:
    u, y, band, _ = _band_case()
    verdict = CompensationGuard().update(u, y, np.zeros(u.size, dtype=bool), band)
    assert verdict.state == "faded" and 0.75 < verdict.ratio < 0.95 and 0.0 < verdict.trust < 1.0


def test_once_off_a_model_in_the_band_stays_off() -> None:
    """Hysteresis: a model the guard would fade in is kept off after an "off" verdict (a
    compliant coupling read 0.75-0.91 for 2 s after 15 s off, and the trial it allowed tracked
    12-21 % worse: BENCHMARKS.md, issue 23)."""
    u, y, band, wrong = _band_case()
    guard = CompensationGuard()
    assert guard.update(u, y, np.zeros(u.size, dtype=bool), wrong).state == "off"
    verdict = guard.adopt(band)
    assert 0.75 < verdict.ratio < 0.95
    assert verdict.state == "off" and verdict.trust == 0.0
    for start in range(0, 6000, 500):  # new samples in the band never bring it back
        part = slice(start, start + 500)
        verdict = guard.update(u[part], y[part], np.zeros(500, dtype=bool), band)
        assert verdict.state == "off" and verdict.trust == 0.0
    assert "at most 75 %" in verdict.reason


def test_back_on_after_min_samples_in_a_row_at_or_below_rho_full() -> None:
    u, y, _, wrong = _band_case()
    # leaves 0.65 of the error: at or below rho_full, not clearly (CLEAR_FIT of it)
    near = GeneralBacklash.ideal(1.0, 0.015, 0.015)
    settings = GuardSettings(window=2000, min_samples=2048)
    guard = CompensationGuard(settings)
    assert guard.update(u, y, np.zeros(u.size, dtype=bool), wrong).state == "off"
    held = guard.adopt(near)
    assert CLEAR_FIT * 0.75 < held.ratio <= 0.75 and held.state == "off"
    assert "judged off before" in held.reason
    states = []
    for start in range(0, 4096, 512):
        part = slice(start, start + 512)
        states.append(guard.update(u[part], y[part], np.zeros(512, dtype=bool), near).state)
    # judged every JUDGE_EVERY (1024) samples: on once 2048 new ones were at or below rho_full
    assert states == ["off", "off", "off", "on", "on", "on", "on", "on"]
    # a model off again, then back in the band and below it: the count starts afresh
    assert guard.adopt(wrong).state == "off"
    assert guard.adopt(near).state == "off"
    assert guard.update(u[:1024], y[:1024], np.zeros(1024, dtype=bool), near).state == "off"
    assert guard.update(u[:1024], y[:1024], np.zeros(1024, dtype=bool), near).state == "on"


def test_reset_forgets_the_off_verdict() -> None:
    u, y, band, wrong = _band_case()
    guard = CompensationGuard()
    guard.update(u, y, np.zeros(u.size, dtype=bool), wrong)
    guard.reset()
    assert guard.update(u, y, np.zeros(u.size, dtype=bool), band).state == "faded"


def test_a_clear_fit_after_an_off_is_back_at_once() -> None:
    u, y, _, wrong = _band_case()
    guard = CompensationGuard()
    assert guard.update(u, y, np.zeros(u.size, dtype=bool), wrong).state == "off"
    clear = guard.adopt(GeneralBacklash.ideal(1.0, 0.02, 0.02))  # leaves about half
    assert clear.ratio > CLEAR_FIT * 0.75 and clear.state == "off"
    verdict = guard.adopt(GeneralBacklash.ideal(1.0, 0.04, 0.04))
    assert verdict.ratio <= CLEAR_FIT * 0.75 and verdict.state == "on"
