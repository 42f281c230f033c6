"""The tracking judge (:class:`TrackingJudge`): tracking with compensation measured against
tracking without it, each over its own readings (the module notes of
:mod:`genbacklash_core.measured`).
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import ArrayLike, FloatArray, IntArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.samples import stamp_steps

from .records import HeldHarm, OfflineBaseline, TrackingVerdict
from .settings import (
    HARM_SHARE,
    OFFLINE_AGREE,
    OFFLINE_CHECK,
    OFFLINE_PROBE,
    RAMP_START,
    RETRY_CHANGE,
    STRONG_HARM,
    TrackingJudgeSettings,
)

_MAX_STEP_S = 0.1  # a gap in one kind's readings counts at most this much of its time


class _Mean:
    """An exponentially time-weighted mean square over one kind's own readings."""

    __slots__ = ("last", "sum", "time", "weight")

    def __init__(self) -> None:
        self.sum = 0.0
        self.weight = 0.0
        self.time = 0.0  # seconds of this kind's readings seen
        self.last: int | None = None  # the stamp of the last one (ns)

    def add(self, stamps: IntArray, errors: FloatArray, window: float) -> None:
        """Readings of this kind in order (stamps in ns), each after the last one added."""
        steps_ns = stamp_steps(stamps, self.last)
        steps = np.minimum(np.maximum(steps_ns / 1e9, 0.0), _MAX_STEP_S)  # np.clip, no NaN here
        ages = steps.cumsum()
        total = float(ages[-1])
        fade = np.exp((ages - total) / window)  # exp(-(age of the newest - age) / window)
        keep = math.exp(-total / window)
        self.sum = self.sum * keep + float(fade @ (errors * errors))
        self.weight = self.weight * keep + float(fade.sum())
        self.time += total
        self.last = int(stamps[-1])

    def rms(self) -> float:
        return math.sqrt(self.sum / self.weight) if self.weight > 0.0 else math.nan


class TrackingJudge:
    """Judges compensation by the tracking error it measures with it and without it.

    Parameters
    ----------
    settings : TrackingJudgeSettings
    """

    def __init__(self, settings: TrackingJudgeSettings | None = None) -> None:
        self.settings = settings or TrackingJudgeSettings()
        self.reset()

    def reset(self) -> None:
        """Forget every reading (identification restarted)."""
        self._on = _Mean()
        self._off = _Mean()
        self._harm_at: float | None = None  # off_time when harm was judged (None: no verdict)
        self._held = False  # the model in use is the one judged harmful: off
        self._play = math.nan  # the play of the model in use
        self._harm_play: float | None = None  # ... when harm was judged
        self._harm_ratio = math.nan  # the ratio harm was judged on
        self._harm_carried = False  # the harm was judged before a restart (hold)
        self._probe_from: float | None = None  # off_time when a probe began
        self._next_probe = self.settings.probe_every  # compensated time of the next probe
        self._on_before = 0.0  # compensated seconds of the means forgotten
        self._trial_done = False  # the trial at part weight passed
        self._offline: OfflineBaseline | None = None  # a checkpoint start's baseline
        self._offline_trial = False  # its first trial, which may pass early
        self._probe_length = self.settings.min_time  # of the probe in progress
        self.verdict = self._judge()

    def start_from(self, baseline: OfflineBaseline) -> TrackingVerdict:
        """Take ``baseline`` (measured offline) as the baseline until the live one is
        probed: compensation is tried from the next reading (module notes)."""
        if not isinstance(baseline, OfflineBaseline):
            raise GenBacklashError(f"baseline must be an OfflineBaseline, got {baseline!r}")
        self._offline = baseline
        self._offline_trial = True
        self.verdict = self._judge()
        return self.verdict

    @property
    def offline(self) -> OfflineBaseline | None:
        """The baseline :meth:`start_from` was given (kept after the live one replaced it
        in the verdicts; None without one, and after :meth:`reset`)."""
        return self._offline

    def live_baseline(self) -> OfflineBaseline | None:
        """The tracking without compensation measured live, for a later start to take.

        Returns
        -------
        OfflineBaseline or None
            ``rms(e_off)`` and the seconds of readings without compensation it was measured
            on, as the verdict's ``off_rms`` and ``off_time`` say once the live baseline is in
            use; None before ``min_time`` seconds of it (the judge would not judge on less)
            or without a finite error above 0. Whether those readings really were without
            compensation on the machine is the caller's to know (``in_loop``).

        Examples
        --------
        >>> judge = TrackingJudge(TrackingJudgeSettings(min_time=1.0))
        >>> t = [k * 1_000_000 for k in range(2000)]
        >>> judge.live_baseline() is None
        True
        >>> base = judge.readings(t, [0.02] * 2000, [0.0] * 2000, [0.0] * 2000)
        >>> round(judge.live_baseline().rms, 6), round(judge.live_baseline().seconds, 3)
        (0.02, 1.999)
        """
        off = self._off
        rms = off.rms()
        if off.time >= self.settings.min_time and math.isfinite(rms) and rms > 0.0:
            return OfflineBaseline(rms, off.time)
        return None

    def held_harm(self) -> HeldHarm | None:
        """The standing verdict of harm, for a later start to hold.

        Returns
        -------
        HeldHarm or None
            Until ``retry`` seconds of readings without compensation have passed since a
            verdict of harm (whether compensation is off for it now, or a model further
            away is tried): the play of the model judged harmful, the ratio it was judged on
            and the seconds held so far; None otherwise (also when the model's play was
            never given by :meth:`new_model`).

        Examples
        --------
        >>> judge = TrackingJudge(TrackingJudgeSettings(min_time=1.0))
        >>> _ = judge.new_model(0.04)
        >>> t = [k * 1_000_000 for k in range(4000)]
        >>> _ = judge.readings(t[:2000], [0.05] * 2000, [0.0] * 2000, [0.0] * 2000)
        >>> _ = judge.readings(t[2000:], [0.08] * 2000, [0.0] * 2000, [1.0] * 2000)
        >>> held = judge.held_harm()
        >>> held.play, round(held.ratio, 2), held.held
        (0.04, 1.6, 0.0)
        """
        play = self._harm_play
        if self._harm_at is None or play is None or not math.isfinite(play):
            return None
        ratio = self._harm_ratio
        if not (math.isfinite(ratio) and ratio > 0.0):
            return None
        return HeldHarm(play, ratio, max(self._off.time - self._harm_at, 0.0))

    def hold(self, harm: HeldHarm) -> TrackingVerdict:
        """Take ``harm`` (judged before a restart) as the standing verdict of harm, as if
        judged here: a model within :data:`RETRY_CHANGE` of ``harm.play`` (or of unknown
        play) is off until ``retry`` seconds of readings without compensation, counted on
        from ``harm.held`` (:meth:`new_model`); returns the verdict.

        Examples
        --------
        >>> judge = TrackingJudge(TrackingJudgeSettings(retry=10.0))
        >>> judge.hold(HeldHarm(0.04, 1.11, 4.0)).state
        'off'
        >>> judge.new_model(0.041).state  # the same model, within 10 %
        'off'
        >>> judge.new_model(0.03).state  # a new model: measured again
        'judging'
        """
        if not isinstance(harm, HeldHarm):
            raise GenBacklashError(f"harm must be a HeldHarm, got {harm!r}")
        if self.settings.in_loop:
            self._harm_at = self._off.time - float(harm.held)
            self._harm_play, self._harm_ratio = float(harm.play), float(harm.ratio)
            self._harm_carried = True
            self._offline_trial = False
            self._held = not math.isfinite(self._play) or self._near_harm(self._play)
            self._measure_afresh(trial=True)
        self.verdict = self._judge()
        return self.verdict

    def _near_harm(self, play: float) -> bool:
        """``play`` lies within :data:`RETRY_CHANGE` of the play judged harmful."""
        harmful = self._harm_play
        if harmful is None or not math.isfinite(harmful):
            return False
        return abs(play - harmful) <= RETRY_CHANGE * abs(harmful)

    def configure(self, settings: TrackingJudgeSettings) -> TrackingVerdict:
        """New settings, the evidence kept; returns the verdict under them."""
        self.settings = settings
        self.verdict = self._judge()
        return self.verdict

    def new_model(self, play: float) -> TrackingVerdict:
        """A model with the play ``play`` (rad) is in use.

        Until ``retry`` seconds after a verdict of harm: a play more than
        :data:`RETRY_CHANGE` away from the one judged harmful is tried (and measured) at
        once, with a trial; one within it is off again, also after such a trial began (an
        estimate that wanders away and back, as a restarted identifier's first ones do, does
        not retry the model judged harmful: measured in BENCHMARKS.md, issue 23). The
        baseline is kept.

        Examples
        --------
        >>> judge = TrackingJudge(TrackingJudgeSettings(retry=10.0))
        >>> judge.hold(HeldHarm(0.04, 1.2, 0.0)).state
        'off'
        >>> judge.new_model(0.046).state, judge.new_model(0.041).state
        ('judging', 'off')
        """
        self._play = float(play)
        if self._harm_at is not None:
            near = self._near_harm(self._play)
            if near != self._held:
                self._held = near
                self._measure_afresh(trial=True)  # a trial for each model tried anew
                self.verdict = self._judge()
        return self.verdict

    def resume(self) -> TrackingVerdict:
        """Compensation comes back after something else held it off for a while (the
        model's guard judged the model off): what was measured compensating before no longer
        says what compensating does now, so it is measured afresh, starting with a trial at
        part weight (the baseline is kept); returns the verdict.

        A seeded start whose trial had passed went back to full weight at once when the
        guard let compensation back 10 s later, on another part of the travel, and tracked
        33 % worse there for 2 s before the judge switched it off (BENCHMARKS.md, issue 23,
        "the guard's hysteresis").

        Examples
        --------
        >>> judge = TrackingJudge(TrackingJudgeSettings(min_time=1.0))
        >>> t = [k * 1_000_000 for k in range(6000)]
        >>> _ = judge.readings(t[:2000], [0.05] * 2000, [0.0] * 2000, [0.0] * 2000)
        >>> for part in (slice(2000, 4000), slice(4000, 6000)):  # a trial, then full weight
        ...     verdict = judge.readings(t[part], [0.01] * 2000, [0.0] * 2000, [1.0] * 2000)
        >>> verdict.state
        'on'
        >>> verdict = judge.resume()
        >>> verdict.state, round(verdict.trust, 2)  # a trial again, from its first weight
        ('judging', 0.05)
        """
        if self.settings.in_loop:
            self._measure_afresh(trial=True)
            self._offline_trial = False
        self.verdict = self._judge()
        return self.verdict

    def readings(
        self,
        stamps: ArrayLike,
        loads: ArrayLike,
        desired: ArrayLike,
        weights: ArrayLike,
    ) -> TrackingVerdict:
        """Add encoder readings (stamps in ns, in order) with the desired position and the
        compensation's weight in force at each; returns the new :attr:`verdict`."""
        t = np.asarray(stamps, dtype=np.int64)
        error = np.asarray(loads, dtype=np.float64) - np.asarray(desired, dtype=np.float64)
        w = np.asarray(weights, dtype=np.float64)
        if not (t.shape == error.shape == w.shape):
            raise GenBacklashError("give as many stamps, loads, desired positions and weights")
        ok = np.isfinite(error)
        compensated = w > 0.0
        window = float(self.settings.window)
        if ok.all() and (compensated.all() or not compensated.any()):  # one kind, all kept
            mean = self._on if compensated.all() else self._off
            if t.size:
                mean.add(t, error, window)
        else:
            for mean, mask in ((self._on, ok & compensated), (self._off, ok & ~compensated)):
                if mask.any():
                    mean.add(t[mask], error[mask], window)
        self.verdict = self._judge()
        return self.verdict

    def _measure_afresh(self, *, trial: bool) -> None:
        """Forget the compensated readings (the baseline is kept); ``trial``: start with a
        trial at part weight again."""
        self._on_before += self._on.time
        self._on = _Mean()
        if trial:
            self._trial_done = False

    def _unprobed(self) -> bool:
        """A start from an offline baseline whose live one (:data:`OFFLINE_PROBE` of
        ``min_time``) is not measured yet."""
        return self._offline is not None and self._off.time < OFFLINE_PROBE * self.settings.min_time

    def _offline_in_use(self) -> OfflineBaseline | None:
        """The offline baseline while no live one of :data:`OFFLINE_PROBE` of ``min_time``
        is measured, and after, while the live one is shorter than ``min_time`` and agrees
        with it within :data:`OFFLINE_AGREE`; else None."""
        offline = self._offline
        if offline is None:
            return None
        if self._unprobed():
            return offline
        live = self._off
        if live.time < self.settings.min_time:
            share = live.rms() / offline.rms
            if 1.0 / OFFLINE_AGREE <= share <= OFFLINE_AGREE:
                return offline  # a second of the live one confirms it, not replaces it
        return None

    def _ratio(self) -> tuple[float, float, float]:
        """``(rms(e_on), rms(e_off), their ratio)`` (NaN where a kind has no readings);
        ``rms(e_off)`` is the offline baseline's while it is in use."""
        offline = self._offline_in_use()
        on_rms = self._on.rms()
        off_rms = offline.rms if offline is not None else self._off.rms()
        return on_rms, off_rms, on_rms / off_rms if off_rms > 0.0 else math.nan

    def _verdict(self, trust: float, state: str, why: str) -> TrackingVerdict:
        on, off = self._on, self._off
        on_rms, off_rms, ratio = self._ratio()
        offline = self._offline_in_use()
        if offline is not None:
            without = f"{off_rms:.3g} rad without, offline over {offline.seconds:.0f} s"
            if not self._unprobed():
                without += f" (a live {off.rms():.3g} over {off.time:.1f} s agrees)"
            off_time, baseline = offline.seconds, "offline"
        else:
            without = f"{off_rms:.3g} rad without over {off.time:.0f} s"
            off_time, baseline = off.time, "measured"
        numbers = (
            f"(measured tracking error {on_rms:.3g} rad rms compensating over {on.time:.0f} s, "
            f"{without})"
        )
        return TrackingVerdict(
            trust,
            state,
            ratio,
            on_rms,
            off_rms,
            on.time,
            off_time,
            f"{why} {numbers}",
            baseline,
            off.time,
        )

    def _judge(self) -> TrackingVerdict:
        """The verdict on the readings so far; moves the judge's own state (a probe begun
        or ended, harm judged, a trial passed)."""
        s = self.settings
        on, off = self._on, self._off
        ratio = self._ratio()[2]
        if not s.in_loop:
            if on.time >= s.min_time and off.time >= s.min_time and ratio < s.ratio_wiring:
                return self._verdict(
                    1.0,
                    "watching",
                    f"tracking is better while compensating ({100 * ratio:.0f} % of the "
                    "error without): the compensated command seems to drive the drivetrain; "
                    "set compensation_in_loop true so the identifier learns from what it sends",
                )
            return self._verdict(
                1.0,
                "watching",
                "not in the loop (compensation_in_loop false): measured tracking watched only",
            )
        if self._probe_from is not None:
            if off.time - self._probe_from < self._probe_length:
                return self._verdict(
                    0.0,
                    "probing",
                    f"compensation held off for {self._probe_length:g} s to measure the "
                    "tracking without it",
                )
            self._probe_from = None
            self._next_probe = self._on_before + on.time + s.probe_every
        if self._harm_at is not None and off.time - self._harm_at >= s.retry:
            self._harm_at = None  # the verdict has run its time: tried again
            if self._held:
                self._held = False
                self._measure_afresh(trial=True)
            return self._judge()
        if self._held:
            when = "measured before this start" if self._harm_carried else "measured"
            judged = ratio if math.isfinite(ratio) else self._harm_ratio
            return self._verdict(
                0.0,
                "off",
                f"compensation off: {when}, it tracked worse than without "
                f"({100 * judged:.0f} % of the error); tried again with a new model or "
                f"after {s.retry:g} s",
            )
        if self._unprobed() and on.time >= OFFLINE_CHECK * s.min_time:
            # the offline baseline checked live before any verdict rests on it
            return self._probe(OFFLINE_PROBE * s.min_time)
        if self._offline is None and off.time < s.min_time:
            # no compensation it could not judge: harm is measured against the baseline, so
            # a trial waits for a full one (a fresh start or a checkpoint's alike)
            return self._verdict(
                0.0,
                "judging",
                f"compensation held off until the tracking without it is measured "
                f"({off.time:.1f} of {s.min_time:g} s)",
            )
        harm_judged = s.min_time * HARM_SHARE  # compensated seconds before clear harm counts
        # clear harm (the ratio above STRONG_HARM times ratio_off) is judged early: each
        # second of it costs tracking
        if on.time >= harm_judged and ratio >= STRONG_HARM * s.ratio_off:
            return self._harm()
        early = (
            self._offline_trial
            and not self._trial_done
            and not self._unprobed()
            and on.time >= harm_judged
            and ratio <= s.ratio_full
        )
        if early:
            # an offline start's trial, judged against the live baseline, clearly helps
            self._offline_trial = False
            self._trial_done = True
            self._measure_afresh(trial=False)  # now judge it at full weight
            return self._judge()
        if on.time < s.min_time:
            if self._trial_done:
                return self._verdict(1.0, "judging", "measuring compensation at full weight")
            # the trial's weight grows with the evidence on it: from RAMP_START of the trial
            # weight to all of it once clear harm can be judged
            grown = RAMP_START + (1.0 - RAMP_START) * min(on.time / harm_judged, 1.0)
            return self._verdict(
                s.trial * grown,
                "judging",
                f"compensation on trial at {100 * s.trial * grown:.0f} % while its tracking "
                "is measured",
            )
        if not self._trial_done:
            if ratio >= s.ratio_off:
                return self._harm()
            self._trial_done = True
            self._measure_afresh(trial=False)  # now judge it at full weight
            return self._judge()
        if self._on_before + on.time >= self._next_probe:
            return self._probe(s.min_time)
        fit = min(max((s.ratio_off - ratio) / (s.ratio_off - s.ratio_full), 0.0), 1.0)
        if fit <= 0.0:
            return self._harm()
        kept = f"measured, compensating keeps {100 * ratio:.0f} % of the tracking error"
        if fit < 1.0:
            return self._verdict(fit, "faded", f"compensation faded to {100 * fit:.0f} %: {kept}")
        return self._verdict(1.0, "on", f"compensation on: {kept}")

    def _harm(self) -> TrackingVerdict:
        self._offline_trial = False
        self._harm_at, self._harm_play, self._held = self._off.time, self._play, True
        self._harm_ratio, self._harm_carried = self._ratio()[2], False
        return self._judge()

    def _probe(self, length: float) -> TrackingVerdict:
        self._probe_from, self._probe_length = self._off.time, length
        return self._judge()
