"""StreamHealth on its own: the fault rules, without a pipeline around them.

The pipeline-level behaviour (pass-through, reports, recovery on real streams) is in
test_faults.py; these pin the rules' edges with hand-made message sequences.
"""

from __future__ import annotations

import numpy as np

from genbacklash_core import CompensatorOptions, Estimate, EstimatorState, GeneralBacklash
from genbacklash_core.structure import Structure
from genbacklash_ros.node.health import (
    FAULT_HOLD_NS,
    LOSS_WINDOW_NS,
    REANCHOR_BACK_NS,
    REANCHOR_COUNT,
    SATURATION_NS,
    SILENCE_UNKNOWN_NS,
    Note,
    StreamHealth,
)
from genbacklash_ros.node.messages import DiagnosticStatus

MS = 1_000_000


NO_MODEL = Estimate.empty(Structure(3))  # the stuck check stays off


class _Sink:
    """A health monitor on its own (what it finds comes back as return values)."""

    def monitor(self) -> StreamHealth:
        return StreamHealth()


def _readings(health: StreamHealth, times: list[int], start_value: float = 0.0) -> None:
    """Regular, changing encoder readings at ``times`` (received when stamped)."""
    last: int | None = None
    previous: float | None = None
    for k, t in enumerate(times):
        value = start_value + 0.001 * k
        assert not health.check_reading(t, last, value, previous, t, [0], [0.0], NO_MODEL).stuck
        last, previous = t, value


def test_a_fault_passes_through_for_the_hold_time_then_clears() -> None:
    health = _Sink().monitor()
    assert not health.passing_through(0)
    health.fault("encoder_spike", DiagnosticStatus.WARN, "a spike", 10 * MS)
    assert health.passing_through(10 * MS + FAULT_HOLD_NS - 1)
    report = health.report(10 * MS + FAULT_HOLD_NS - 1)
    assert report.passing and report.level == DiagnosticStatus.WARN
    assert report.active == ("encoder_spike",) and "a spike" in report.parts
    assert health.report(10 * MS + FAULT_HOLD_NS - 1).parts[1:] == []  # each text once
    assert not health.passing_through(10 * MS + FAULT_HOLD_NS)
    assert health.report(10 * MS + FAULT_HOLD_NS).level == DiagnosticStatus.OK


def test_a_later_sign_prolongs_and_a_higher_level_wins() -> None:
    health = _Sink().monitor()
    health.fault("x", DiagnosticStatus.ERROR, "bad", 0)
    health.fault("x", DiagnosticStatus.WARN, "", 300 * MS)
    assert health.faults["x"] == (DiagnosticStatus.ERROR, 300 * MS + FAULT_HOLD_NS)


def test_a_clock_jump_back_needs_a_run_of_far_back_messages() -> None:
    health = _Sink().monitor()
    last = 10_000 * MS
    back = last - 2 * REANCHOR_BACK_NS
    # a single message a little back is out of order, never a jump
    assert health.jumped_back("encoder", last - REANCHOR_BACK_NS + 1, last) is None
    for k in range(REANCHOR_COUNT - 1):
        assert health.jumped_back("encoder", back + k * MS, last) is None
    jump = health.jumped_back("encoder", back + (REANCHOR_COUNT - 1) * MS, last)
    assert jump is not None and abs(jump - 2 * REANCHOR_BACK_NS) <= 2 * MS
    # an accepted message in between breaks the run
    health = _Sink().monitor()
    assert health.jumped_back("command", back, last) is None
    health.check_command(last + MS, 0.0, last + MS, CompensatorOptions())
    for k in range(REANCHOR_COUNT - 1):
        assert health.jumped_back("command", back + (k + 1) * MS, last) is None


def test_encoder_silence_is_seen_from_a_command_on_the_receive_clock() -> None:
    sink = _Sink()
    health = sink.monitor()
    _readings(health, [0, MS])
    options = CompensatorOptions()
    health.check_command(MS + SILENCE_UNKNOWN_NS, 0.0, MS + SILENCE_UNKNOWN_NS, options)
    assert "encoder_silent" not in health.faults  # not yet longer than the limit
    now = 2 * MS + SILENCE_UNKNOWN_NS
    events = health.check_command(now, 0.0, now, options)
    assert events == [Note("encoder silent for 1.001 s")]  # returned, not called back
    assert health.faults["encoder_silent"][0] == DiagnosticStatus.ERROR
    assert any("encoder silent for 1.001 s" in part for part in health.report(now).parts)


def test_lost_readings_are_a_fault_once_the_period_is_known() -> None:
    health = _Sink().monitor()
    regular = list(range(0, 2 * LOSS_WINDOW_NS, MS))  # 1 kHz: the period is learnt
    _readings(health, regular)
    assert not health.faults
    rng = np.random.default_rng(7)
    start = regular[-1] + MS
    times = np.arange(start, start + 2 * LOSS_WINDOW_NS, MS)
    kept = times[rng.random(times.size) > 0.4].tolist()  # 40 % lost
    last, previous = regular[-1], 0.0
    for k, t in enumerate(kept):
        health.check_reading(t, last, 1.0 + 0.001 * k, previous, t, [0], [0.0], NO_MODEL)
        last, previous = t, 1.0 + 0.001 * k
    assert "encoder_loss" in health.faults
    assert any("encoder lost" in part for part in health.report(last).parts)


def test_a_command_at_its_limit_for_long_enough_is_saturated() -> None:
    health = _Sink().monitor()
    options = CompensatorOptions(u_min=-1.0, u_max=1.0)
    for t in range(0, SATURATION_NS, 10 * MS):
        health.check_command(t, 1.0, t, options)
    assert "command_saturated" not in health.faults
    health.check_command(SATURATION_NS, 1.5, SATURATION_NS, options)
    assert "command_saturated" in health.faults
    # a command inside the limits restarts the count
    health = _Sink().monitor()
    for t in range(0, SATURATION_NS + 1, 10 * MS):
        health.check_command(t, 1.0 if t != 100 * MS else 0.5, t, options)
    assert "command_saturated" not in health.faults


def test_reset_forgets_every_fault() -> None:
    health = _Sink().monitor()
    health.fault("encoder_stuck", DiagnosticStatus.ERROR, "stuck", 0)
    health.reset()
    assert not health.faults and not health.report(0).parts


def _converged(model: GeneralBacklash) -> Estimate:
    return Estimate(
        Structure(1),
        np.array(model.parameters()),
        np.eye(4) * 1e-10,
        residual=1e-4,
        excitation=0.5,
        state=EstimatorState.CONVERGED,
        confidence=0.99,
        samples=10_000,
    )


def test_an_encoder_dithering_by_one_count_is_no_spike() -> None:
    """A quantised encoder at rest toggles between two counts. The errors' scale falls to
    its floor while the load rests, below one count; a one-count change is still no spike
    (the limit is at least SPIKE_COUNTS counts), while a jump of 20 counts is one."""
    count = 2 * np.pi / 4096
    model = GeneralBacklash((1.0,), 0.05, (1.0,), 0.05)
    est = _converged(model)
    health = StreamHealth()
    rest = 65 * count  # inside the dead band of u = rest
    u = np.full(100, rest)
    times = np.arange(100) * MS
    still = np.full(100, rest)
    for k in range(10):  # the load rests: the scale falls to its floor
        assert health.screen(times + k * 100 * MS, u, still, est).keep is None
    dither = rest + count * (np.arange(100) % 7 == 3)
    screening = health.screen(times + 1000 * MS, u, dither, est)
    assert screening.keep is None and screening.events == []
    spike = dither.copy()
    spike[50] += 20 * count
    screening = health.screen(times + 1100 * MS, u, spike, est)
    assert screening.keep is not None
    assert np.flatnonzero(~screening.keep).tolist() == [50]
    assert [e.key for e in screening.events] == ["encoder_spike"]


def _moving(seed: int, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A backlash driven back and forth, read by a noisy encoder: (times, u, y)."""
    rng = np.random.default_rng(seed)
    u = 0.8 * np.sin(np.arange(n) * 2 * np.pi / 400.0)
    x = np.zeros(n)
    for k in range(n):  # the play operator (eq. 20) of an ideal backlash, gap 0.05 each side
        prev = x[k - 1] if k else 0.0
        x[k] = min(max(prev, u[k] - 0.05), u[k] + 0.05)
    return np.arange(n, dtype=np.int64) * MS, u, x + rng.normal(0.0, 1e-4, n)


def test_a_feed_is_screened_in_steps_whatever_its_size() -> None:
    """One feed of 640 samples is judged as ten feeds of 64 are: the same samples kept, the
    same drops, the same residual scale after it; a spike deep inside the large feed is
    caught with the scale of its own step."""
    model = GeneralBacklash((1.0,), 0.05, (1.0,), 0.05)
    est = _converged(model)
    times, u, y = _moving(3, 1280)
    y[900] += 0.05  # a spike in the second half
    one, many = StreamHealth(), StreamHealth()
    for health in (one, many):  # the same history: a scale learnt on the first half
        for k in range(0, 640, 64):
            assert health.screen(times[k : k + 64], u[k : k + 64], y[k : k + 64], est).keep is None
    whole = one.screen(times[640:], u[640:], y[640:], est)
    parts = [
        many.screen(times[k : k + 64], u[k : k + 64], y[k : k + 64], est)
        for k in range(640, 1280, 64)
    ]
    keep = np.concatenate([np.ones(64, bool) if p.keep is None else p.keep for p in parts])
    assert whole.keep is not None and np.array_equal(whole.keep, keep)
    assert np.flatnonzero(~whole.keep).tolist() == [900 - 640]
    assert (
        [e.key for e in whole.events]
        == [e.key for p in parts for e in p.events]
        == ["encoder_spike"]
    )
    assert one._spikes.scale == many._spikes.scale  # the scale followed each step alike


COUNT = 2 * np.pi / 4096  # one count of a 4096 counts/rev encoder


def _jogs(steps: int, lag: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A load nudged up by short jogs, read by a quantised encoder: (times, u, y, resumed)
    in steps of 64 samples, each 30 samples of a command inside the play, 10 of a jog that
    pushes the right flank, 24 inside the play again. The drivetrain's right dead zone is
    ``lag`` wider than the model's (0.05): the model's band lags its wear. The samples
    after a command change are marked resumed, as the settling rule marks them (the
    samples it took out are not there: the servo is ideal)."""
    u = np.empty(64 * steps)
    resumed = np.zeros(u.size, dtype=bool)
    for k in range(steps):
        jog = 0.07 + 0.01 * k
        u[64 * k : 64 * k + 64] = jog - 0.03
        u[64 * k + 30 : 64 * k + 40] = jog
        resumed[[64 * k, 64 * k + 30, 64 * k + 40]] = True
    x = np.empty_like(u)
    previous = 0.0
    for k, value in enumerate(u):  # the play operator (eq. 20), c_L 0.05, c_R 0.05 + lag
        previous = x[k] = min(max(previous, value - 0.05 - lag), value + 0.05)
    times = np.arange(u.size, dtype=np.int64) * MS
    y = np.round(x / COUNT) * COUNT
    y[10:12] += COUNT  # a flicker of one count at first: the screen learns the count
    return times, u, y, resumed


def _screen_steps(
    health: StreamHealth, times: np.ndarray, u: np.ndarray, y: np.ndarray, resumed: np.ndarray
) -> list[int]:
    """Feed (times, u, y, resumed) in steps of 64 with a converged estimate of the model
    the jogs lag (c_L = c_R = 0.05); the indices of the samples taken out."""
    est = _converged(GeneralBacklash((1.0,), 0.05, (1.0,), 0.05))
    out: list[int] = []
    for k in range(0, u.size, 64):
        part = slice(k, k + 64)
        screening = health.screen(times[part], u[part], y[part], est, resumed[part])
        if screening.keep is not None:
            out += (k + np.flatnonzero(~screening.keep)).tolist()
    return out


def test_a_band_that_lags_the_wear_is_no_spike() -> None:
    """While the play grows the estimate lags it: the readings pushed by a flank sit a few
    counts outside the model's band (here 4 counts, above the limit of a screen whose
    errors are mostly those of a resting load). They are no spike: each reading follows
    the one before it (the issue 22 regression: the bundled operation bag lost 7 readings
    so, with the settling rule on)."""
    times, u, y, resumed = _jogs(20, 4 * COUNT)
    health = StreamHealth()
    assert _screen_steps(health, times, u, y, resumed) == []
    assert health._spikes._shift[0] < -2 * COUNT  # the screen learnt where the lower edge is


def test_spikes_are_still_caught_on_a_lagging_band() -> None:
    """Isolated readings 10-40 counts off, pushed or resting, are taken out, and only
    they."""
    times, u, y, resumed = _jogs(20, 4 * COUNT)
    spikes = {200: 20, 420: -10, 675: 40, 995: -25, 1100: 15}  # in jogs and at rest
    for k, counts in spikes.items():
        y[k] += counts * COUNT
    assert _screen_steps(StreamHealth(), times, u, y, resumed) == sorted(spikes)


def test_no_spike_is_judged_while_the_guard_says_the_model_does_not_fit() -> None:
    """A reading far from the prediction of a model that does not describe the drivetrain
    (the compensation guard off) is no evidence of a spike: nothing is taken out then, and
    the same readings are screened again once the model fits."""
    times, u, y, resumed = _jogs(20, 4 * COUNT)
    spikes = {200: 20, 420: -10, 675: 40, 995: -25, 1100: 15}
    for k, counts in spikes.items():
        y[k] += counts * COUNT
    health = StreamHealth()
    health.model_fits = False
    assert _screen_steps(health, times, u, y, resumed) == []
    health = StreamHealth()
    assert health.model_fits  # the default: screened
    assert _screen_steps(health, times, u, y, resumed) == sorted(spikes)


def test_a_spike_judged_by_the_band_alone_does_not_take_the_readings_after_it() -> None:
    """A reading after samples taken out while the servo settled is judged by the band
    alone: a spike that stays inside the band passes that test. The readings after it do
    not follow it, and follow each other: it is the isolated one, and they are fed."""
    times, u, y, resumed = _jogs(12, 0.0)
    spike = 64 * 8 + 40  # resting inside the play, the first sample after a jog
    y[spike] += 12 * COUNT
    assert _screen_steps(StreamHealth(), times, u, y, resumed) == [spike]


def _overshoot(u: np.ndarray, y: np.ndarray, at: int, counts: list[int]) -> None:
    """The load of ``_jogs`` (no lag) carried on past the flank that pushed it at ``at``, by
    ``counts`` more at the readings after it, into the play; from there the play operator
    (eq. 20) again, read by the encoder (in place)."""
    position = float(y[at])
    for k, extra in enumerate(counts, start=at + 1):
        y[k] = position + extra * COUNT
    previous = float(y[at + len(counts)])
    for k in range(at + len(counts) + 1, u.size):
        previous = min(max(previous, u[k] - 0.05), u[k] + 0.05)
        y[k] = np.round(previous / COUNT) * COUNT


def test_a_load_travelling_at_its_own_pace_after_a_settling_gap_is_no_spike() -> None:
    """The physics drivetrains (issue 22, 20 clean seeds each): after samples taken out while
    the servo settled, the load moves at a pace the model does not predict, and the first
    reading (judged by the band alone) was taken out as the isolated one because the
    readings after it lead back beside it on a straight line.

    * gravity, seed 2: inside the play the load falls across the gap, slowing (6, 3, 1
      counts a reading); the model holds a load there (eq. 20);
    * near_ideal, seed 11: the load pushed up a flank by a jog carries on past it into the
      play, slowing (6, 3, 1 counts);
    * gravity, seeds 6 and 7: a load behind the flank a jog moved (the servo trails the
      command) closes on it reading by reading (6, 2, 1 counts behind, then on it).

    Readings that travel one way are the load's: nothing is taken out, and the resting spike
    of the band-alone test above is still caught beside them."""
    for case in ("fall", "carry on", "trail"):
        times, u, y, resumed = _jogs(12, 0.0)
        if case == "fall":
            at = 64 * 8 + 40  # resting inside the play, the first sample after a jog
            assert resumed[at]
            y[at : at + 4] = y[at] + np.array([0, -6, -9, -10]) * COUNT
            y[at + 4 : 64 * 9] = y[at + 3]
        elif case == "carry on":
            at = 64 * 6 + 30  # the first sample of a jog: the load pushed up the flank
            assert resumed[at]
            _overshoot(u, y, at, [6, 9, 10])
        else:
            at = 64 * 7 + 30  # the first sample of a jog, the load still behind the flank
            assert resumed[at]
            y[at : at + 3] -= np.array([6, 2, 1]) * COUNT
        assert _screen_steps(StreamHealth(), times, u, y, resumed) == [], case
        spike = 64 * 5 + 40
        y[spike] += 12 * COUNT
        assert _screen_steps(StreamHealth(), times, u, y, resumed) == [spike], case


def test_a_reading_exactly_the_counts_floor_away_is_within_the_limit() -> None:
    """The limit's floor is ``SPIKE_COUNTS`` counts: a reading that far from a prediction
    that is itself a reading is within it, whatever the rounding of their difference (the
    physics gravity record, seed 15, lost a reading 2 counts on from the one before it, at
    the end of a feed where no reading after it could vouch for it). Here the last reading
    of each step, resting inside the play, moves by 2 counts, up or down."""
    times, u, y, resumed = _jogs(12, 0.0)
    for k in range(2, 12):
        end = 64 * k + 63
        y[end] = y[end - 1] + (2 if k % 2 else -2) * COUNT
    assert _screen_steps(StreamHealth(), times, u, y, resumed) == []
