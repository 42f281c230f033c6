"""Does the compensation help? A guard that judges it from the data and fades it out if not.

The inverse compensator sends ``u = B^-1(r)`` for a desired load position ``r``, so the
load ends at ``y = B_true(u)`` and the tracking error it leaves is the model's own error at
the commands sent, ``y - r = B_true(u) - B(u)``. Without compensation the error would be
``B_true(r) - r``: what a model with no play ("the load is where the command is") gets
wrong. Both can be measured from the samples the identifier is fed, whatever the commands
were:

* the **model error** ``e_m = y - B(u)``, the free-run simulation of the estimate in use on
  the commands ``u`` the gear received (eq. 8 run forward: the play operator of the paper's
  general backlash), compared with
* the **no-model error** ``e_0 = y - u``.

Their ratio ``rho = rms(e_m) / rms(e_0)`` (exponentially weighted over a window of samples)
is what the compensation keeps of the tracking error: about 0 where the model describes the
drivetrain, 1 or more where it does not (a servo lag, a load that coasts into the play, a
compliant coupling: effects the play operator lacks; or an estimate of the play far from the
truth). The guard's **trust** is 1 below ``rho_full``, 0 above ``rho_off`` and linear in
between, once ``min_samples`` samples have been judged with a model (before that it moves
from 1, the estimate's confidence gate alone, towards that value as the evidence grows); the
node multiplies the estimate's confidence by it, so compensation fades out where it would
not help and the reason is said.

Once the guard has judged compensation off, it comes back only after ``min_samples`` *new*
samples in a row judged at or below ``rho_full``, or at once for a model that leaves at most
:data:`CLEAR_FIT` of ``rho_full`` (hysteresis): a new model is judged at once on the samples
remembered, the samples it was fitted on, and a model that reads near the fade band there
after an "off" is not evidence enough to compensate on; one far below it (a first estimate
replaced by a good one) is. On a compliant coupling after 15 s off a restarted node's models
read 0.75-0.91, the guard faded compensation in, and the trial it allowed tracked 12-21 %
worse than no compensation (BENCHMARKS.md, issue 23, "the guard's hysteresis").

Examples
--------
>>> import numpy as np
>>> from genbacklash_core import GeneralBacklash, simulate_backlash
>>> true = GeneralBacklash.ideal(1.0, 0.05, 0.05)
>>> u = 0.3 * np.sin(np.linspace(0.0, 40.0, 4000))
>>> y = simulate_backlash(true, u)
>>> guard = CompensationGuard(GuardSettings(window=2000, min_samples=500))
>>> guard.update(u, y, np.zeros(u.size, dtype=bool), true).state
'on'
>>> wrong = GeneralBacklash.ideal(1.0, 0.15, 0.15)  # three times the play
>>> guard = CompensationGuard(GuardSettings(window=2000, min_samples=500))
>>> verdict = guard.update(u, y, np.zeros(u.size, dtype=bool), wrong)
>>> verdict.state, verdict.trust
('off', 0.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._typing import FloatArray
from .backlash import GeneralBacklash
from .cascade import Cascade
from .errors import GenBacklashError
from .play import play_operator
from .simulate import play_bounds

__all__ = [
    "CLEAR_FIT",
    "HISTORY",
    "JUDGE_EVERY",
    "CompensationGuard",
    "GuardSettings",
    "GuardVerdict",
    "free_run",
]

JUDGE_EVERY = 1024
"""Samples the guard lets gather before it judges them (a new model is judged at once)."""

CLEAR_FIT = 0.5
"""After a verdict of "off", a model whose error ratio is at most this share of ``rho_full``
brings compensation back at once; one between it and ``rho_full`` only after ``min_samples``
new samples in a row (module notes, hysteresis)."""

HISTORY = 3
"""Windows of samples the guard remembers to judge a new model on (the exponential weight
of older samples is below exp(-3), 5 %)."""


@dataclass(frozen=True)
class GuardSettings:
    """How the guard judges the compensation.

    Parameters
    ----------
    window : int
        Samples of the exponential window (``e``-folding length) over which both errors'
        mean squares are taken.
    min_samples : int
        Samples judged with a model before the guard's judgement counts in full; before,
        trust moves linearly from 1 towards it with the evidence. Also the new samples in
        a row at or below ``rho_full`` that bring compensation back after an "off".
    rho_full, rho_off : float
        The error ratio ``rho`` at or below which compensation is applied in full, and at or
        above which it is off; linear in between (``0 < rho_full < rho_off``).
    enabled : bool
        False: trust is always 1; the guard only judges (its state and reason still say
        whether compensation helps).

    Examples
    --------
    >>> try:
    ...     GuardSettings(rho_full=0.9, rho_off=0.5)
    ... except GenBacklashError as err:
    ...     print(err)
    rho_full must be > 0 and below rho_off, got 0.9 and 0.5
    """

    window: int = 5000
    min_samples: int = 1000
    rho_full: float = 0.75
    rho_off: float = 0.95
    enabled: bool = True

    def __post_init__(self) -> None:
        if not (isinstance(self.window, int) and self.window >= 1):
            raise GenBacklashError(f"window must be a whole number >= 1, got {self.window!r}")
        if not (isinstance(self.min_samples, int) and self.min_samples >= 0):
            raise GenBacklashError(
                f"min_samples must be a whole number >= 0, got {self.min_samples!r}"
            )
        full, off = float(self.rho_full), float(self.rho_off)
        if not (math.isfinite(full) and math.isfinite(off) and 0.0 < full < off):
            raise GenBacklashError(
                f"rho_full must be > 0 and below rho_off, got {self.rho_full} and {self.rho_off}"
            )


@dataclass(frozen=True)
class GuardVerdict:
    """The guard's judgement after a batch.

    Attributes
    ----------
    trust : float
        In ``[0, 1]``: the factor on the estimate's confidence.
    state : str
        ``"judging"`` (no sample judged yet: trust 1), ``"on"`` (trust 1), ``"faded"`` or
        ``"off"`` (trust 0).
    ratio : float
        ``rho = rms(y - B(u)) / rms(y - u)`` over the window (NaN before any sample).
    model_rms, no_model_rms : float
        The two root-mean-square errors over the window (rad).
    samples : int
        Samples judged with a model so far.
    reason : str
        One sentence: why compensation is on, faded or off.
    """

    trust: float
    state: str
    ratio: float
    model_rms: float
    no_model_rms: float
    samples: int
    reason: str


_JUDGING = "no samples judged with a model yet: the estimate's confidence alone gates"


class CompensationGuard:
    """Judges, batch by batch, whether compensating with a model helps (module notes).

    Parameters
    ----------
    settings : GuardSettings
    """

    def __init__(self, settings: GuardSettings | None = None) -> None:
        self.settings = settings or GuardSettings()
        # decay**k for k = 0, 1, ... (the window's weights, :meth:`_weights`), and its decay
        self._powers: FloatArray = np.ones(0)
        self._powers_decay = math.nan
        self.reset()

    def reset(self) -> None:
        """Forget every judgement (a restart of identification)."""
        # the latest samples (up to HISTORY windows): a new model is judged on them at once
        self._history: list[tuple[FloatArray, FloatArray, np.ndarray]] = []
        self._held = 0
        # samples not judged yet (judged JUDGE_EVERY at a time, with the model in use)
        self._pending: list[tuple[FloatArray, FloatArray, np.ndarray]] = []
        self._waiting = 0
        self._model: GeneralBacklash | Cascade | None = None
        self._x: float | None = None  # the model's free-run output after the last sample
        self._sum_model = 0.0  # exponentially weighted sums of the squared errors
        self._sum_none = 0.0
        self._weight = 0.0  # exponentially weighted sample count
        self._samples = 0
        self._was_off = False  # judged off, and not back on since (hysteresis)
        self._recovered = 0  # new samples judged at or below rho_full since then, in a row
        self._unjudged = 0  # samples remembered since the last judgement
        self.verdict: GuardVerdict = self._judge()

    def configure(self, settings: GuardSettings) -> GuardVerdict:
        """New settings, the evidence kept; returns the verdict under them."""
        self.settings = settings
        if self._weight > 0.0:
            self.verdict = self._judge()
        return self.verdict

    def update(
        self,
        us: FloatArray,
        ys: FloatArray,
        breaks: np.ndarray,
        model: GeneralBacklash | Cascade | None,
    ) -> GuardVerdict:
        """Judge a batch of samples (the gear's input ``us``, the load ``ys``; ``breaks[k]``:
        the drivetrain's path from sample ``k - 1`` to sample ``k`` is not known, and the
        free run restarts at the measured load there) with ``model``, the model the
        compensator used for them. Returns the new :attr:`verdict`.

        Give breaks only where readings were lost or taken out: the compensator runs open
        loop on its own commands, and a restart at every break of a chain broken by stamps
        alone re-anchors the model on the measured load where it is judged, hiding a load
        that coasts into the play (the node passes its screen's ``restarts``, not its
        sample rule's breaks: BENCHMARKS.md, the live demo, branch coast2-1)."""
        u = np.asarray(us, dtype=np.float64)
        y = np.asarray(ys, dtype=np.float64)
        if u.size == 0:
            return self.verdict
        brk = np.asarray(breaks, dtype=bool)
        self._remember(u, y, brk)
        if model is None:
            self._x = None
            self._pending.clear()
            self._waiting = 0
            return self.verdict
        if model is not self._model and model != self._model:
            return self.adopt(model)  # the batch is in the history it is judged on
        self._pending.append((u, y, brk))
        self._waiting += u.size
        if self._waiting >= JUDGE_EVERY:
            self.flush()
        return self.verdict

    def flush(self) -> GuardVerdict:
        """Judge the samples waiting (batches are judged :data:`JUDGE_EVERY` samples at a
        time) with the model in use now; returns the verdict."""
        pending, model = self._pending, self._model
        if pending and model is not None:
            u = np.concatenate([p[0] for p in pending])
            y = np.concatenate([p[1] for p in pending])
            brk = np.concatenate([p[2] for p in pending])
            self._judge_batch(u, y, brk, model)
            self._recover()
            self.verdict = self._judge()
        pending.clear()
        self._waiting = 0
        return self.verdict

    def adopt(self, model: GeneralBacklash | Cascade | None) -> GuardVerdict:
        """A new model is in use: judge it at once on the samples remembered (the last
        ``HISTORY`` windows), so that its verdict does not wait for new evidence."""
        if model is None or model is self._model or model == self._model:
            self._model = model if model is not None else self._model
            return self.verdict
        self._model = model
        self._x = None
        self._sum_model = self._sum_none = self._weight = 0.0
        self._samples = 0
        self._pending.clear()  # they are in the history judged below
        self._waiting = 0
        if self._history:
            u = np.concatenate([h[0] for h in self._history])
            y = np.concatenate([h[1] for h in self._history])
            brk = np.concatenate([h[2] for h in self._history])
            brk[0] = True
            self._judge_batch(u, y, brk, model)
        self._recover()
        self.verdict = self._judge()
        return self.verdict

    def _recover(self) -> None:
        """After a verdict of "off": count the samples that arrived since the last judgement
        (not the remembered ones a new model is judged on again) towards coming back on, if
        the ratio is at or below ``rho_full`` now; start the count again if not (module
        notes, hysteresis)."""
        new, self._unjudged = self._unjudged, 0
        if not self._was_off:
            return
        if self._weight > 0.0 and self._errors()[2] <= self.settings.rho_full:
            self._recovered += new
        else:
            self._recovered = 0

    def _errors(self) -> tuple[float, float, float]:
        """``(rms(e_m), rms(e_0), rho)`` over the window (``self._weight`` above 0)."""
        model_rms = math.sqrt(self._sum_model / self._weight)
        none_rms = math.sqrt(self._sum_none / self._weight)
        ratio = model_rms / none_rms if none_rms > 0 else (0.0 if model_rms == 0 else math.inf)
        return model_rms, none_rms, ratio

    def _remember(self, u: FloatArray, y: FloatArray, brk: np.ndarray) -> None:
        history = self._history
        history.append((u, y, brk))
        self._held += u.size
        self._unjudged += u.size
        cap = HISTORY * self.settings.window
        while self._held - history[0][0].size >= cap:
            self._held -= history.pop(0)[0].size

    def _judge_batch(
        self, u: FloatArray, y: FloatArray, brk: np.ndarray, model: GeneralBacklash | Cascade
    ) -> None:
        """Run the model free on one batch and add both errors to the window."""
        backlash = model.backlash if isinstance(model, Cascade) else model
        if brk.size and brk[0]:
            self._x = None  # the batch does not follow the last one
        try:
            predicted = free_run(backlash, u, y, brk, self._x)
        except GenBacklashError:  # a branch not finite somewhere: stretch by stretch
            predicted = self._free_run_by_stretch(backlash, u, y, brk)
        self._x = float(predicted[-1]) if predicted.size else self._x
        self._accumulate(y - predicted, y - u)

    def _free_run_by_stretch(
        self, backlash: GeneralBacklash, u: FloatArray, y: FloatArray, brk: np.ndarray
    ) -> FloatArray:
        """:func:`free_run` one stretch between breaks at a time; a stretch whose branches
        are not finite is predicted NaN (left out of the window)."""
        starts = [0, *(np.flatnonzero(brk[1:]) + 1).tolist()]
        ends = [*starts[1:], u.size]
        predicted = np.empty_like(y)
        x = self._x
        for start, stop in zip(starts, ends, strict=True):
            part = slice(start, stop)
            try:
                predicted[part] = free_run(
                    backlash, u[part], y[part], np.zeros(stop - start, bool), x
                )
            except GenBacklashError:
                predicted[part] = np.nan
            x = None  # the next stretch starts at its measured load
        return predicted

    def _accumulate(self, e_model: FloatArray, e_none: FloatArray) -> None:
        ok = np.isfinite(e_model) & np.isfinite(e_none)
        e_model, e_none = e_model[ok], e_none[ok]
        n = e_model.size
        if n == 0:
            return
        decay = math.exp(-1.0 / self.settings.window)
        w = self._weights(decay, n)
        old = decay**n
        self._sum_model = self._sum_model * old + float(w @ (e_model * e_model))
        self._sum_none = self._sum_none * old + float(w @ (e_none * e_none))
        self._weight = self._weight * old + float(w.sum())
        self._samples += n

    def _weights(self, decay: float, n: int) -> FloatArray:
        """The weights of a batch of ``n`` samples, newest 1: ``decay**(n-1-k)``.

        The powers are computed once per decay (``decay ** arange``, element by element the
        same numbers as computing them for each batch: tests/core/test_guard.py) and each
        batch takes a reversed copy of their first ``n``: a new model is judged on every
        sample remembered, and the power of each was most of the cost
        (BENCHMARKS.md "Replay throughput").
        """
        powers = self._powers
        if decay != self._powers_decay or powers.size < n:
            size = max(n, 2 * powers.size) if decay == self._powers_decay else n
            powers = decay ** np.arange(size, dtype=np.float64)
            self._powers, self._powers_decay = powers, decay
        return powers[n - 1 :: -1].copy() if n else powers[:0].copy()

    def _judge(self) -> GuardVerdict:
        s = self.settings
        if self._weight <= 0.0:
            nan = math.nan
            return GuardVerdict(1.0, "judging", nan, nan, nan, 0, _JUDGING)
        model_rms, none_rms, ratio = self._errors()
        fit = min(max((s.rho_off - ratio) / (s.rho_off - s.rho_full), 0.0), 1.0)
        evidence = 1.0 if s.min_samples == 0 else min(self._samples / s.min_samples, 1.0)
        # without evidence the confidence gate alone decides; with it, the fit
        judged = 1.0 - evidence * (1.0 - fit)
        kept = f"the model leaves {100 * ratio:.0f} % of the tracking error"
        numbers = (
            f"(model error {model_rms:.4g} rad rms against {none_rms:.4g} rad without "
            f"compensation, over the last {min(self._samples, s.window)} samples)"
        )
        held = (
            self._was_off
            and evidence >= 1.0
            and ratio > CLEAR_FIT * s.rho_full
            and self._recovered < max(s.min_samples, 1)
        )
        if held and judged > 0.0:
            # hysteresis: once off, back on only after min_samples new samples at or below
            # rho_full in a row
            judged = 0.0
            state = "off"
            why = (
                f"compensation off: judged off before and back on only after "
                f"{max(s.min_samples, 1)} new samples in a row in which the model leaves at "
                f"most {100 * s.rho_full:.0f} % of the tracking error ({self._recovered} so "
                f"far; now {100 * ratio:.0f} %), or at once below "
                f"{100 * CLEAR_FIT * s.rho_full:.0f} %"
            )
        elif judged == 0.0:
            state = "off"
            why = (
                f"compensation off: {kept}, at or above {100 * s.rho_off:.0f} %; the model "
                "does not describe this drivetrain well enough to cancel its play"
            )
        elif judged < 1.0:
            state = "faded"
            why = f"compensation faded to {100 * judged:.0f} %: {kept}"
        else:
            state, why = "on", f"compensation on: {kept}"
        if evidence >= 1.0:
            self._was_off = judged == 0.0
            if not self._was_off:
                self._recovered = 0
        trust = judged
        if not s.enabled:
            trust, why = 1.0, f"guard disabled, compensation kept in full; judged: {why}"
        return GuardVerdict(
            trust, state, ratio, model_rms, none_rms, self._samples, f"{why} {numbers}"
        )


def free_run(
    model: GeneralBacklash,
    u: FloatArray,
    y: FloatArray,
    breaks: np.ndarray,
    x_prev: float | None = None,
) -> FloatArray:
    """The backlash run free on the commands ``u`` (eq. 8), restarted at the measured load
    after every break: at a sample where ``breaks`` is true (and at the first one when
    ``x_prev`` is None) the state is the measured ``y`` clamped into the play there; from
    there on it follows the play operator. One play-operator scan over the whole batch (a
    restart is a clamp to a single value), exactly what a simulation per stretch between
    breaks gives (:func:`~genbacklash_core.simulate.simulate_backlash` from the clamped
    reading), at the cost of one: the guard judges several thousand samples with a break
    every few samples (the servo's settling rule) each time a new estimate is adopted.

    Raises :class:`~genbacklash_core.errors.GenBacklashError` when a branch is not finite.

    >>> bl = GeneralBacklash.ideal(1.0, 0.5, 0.5)
    >>> u = np.array([0.0, 1.0, 0.8, 0.0, 2.0, 1.9])
    >>> y = np.array([0.0, 0.5, 0.5, 0.5, 0.3, 1.5])
    >>> free_run(bl, u, y, np.array([False, False, False, False, True, False]), 0.0).tolist()
    [0.0, 0.5, 0.5, 0.5, 1.5, 1.5]
    """
    left, right = model.left(u), model.right(u)
    if not (np.all(np.isfinite(left)) and np.all(np.isfinite(right))):
        raise GenBacklashError("a branch of the model is not finite on these commands")
    lo, hi = play_bounds(left, right)
    restart = np.array(breaks, dtype=bool, copy=True)
    if restart.size and x_prev is None:
        restart[0] = True
    start = np.minimum(np.maximum(y[restart], lo[restart]), hi[restart])
    lo[restart] = start
    hi[restart] = start
    return play_operator(lo, hi, 0.0 if x_prev is None else x_prev)
