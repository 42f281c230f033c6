"""The discrepancy loop: measure the gap, name the missing effect, add it, re-measure.

1. Fit the starting model (the ideal backlash of eq. 1 unless told otherwise) on the
   estimation segment and measure its validation gap.
2. The estimation residual is tested against white noise independent of the input (Ljung-Box,
   input cross-correlation, higher-order correlations), and every applicable detector of the
   catalog looks for its signature; those whose signature passes its threshold nominate their
   effect. If none does, stop. (The detectors run even on a residual that passes the generic
   tests: with a white input a drifting gap, say, leaves a white residual uncorrelated with
   the input, which only its own signature reveals.)
3. Effects that mimic each other are told apart in the detectors, by their evidence: a dead
   time and a lag by the shape of the error step response (a box or a decay), so only the one
   the evidence points to is nominated (both when it is unclear).
4. Each nominee's augmentation is fitted on the estimation data (a physical effect also
   behind the servo's lag, :func:`~.effects._physics.servo_base`; fitted so, it must pass
   the acceptance test against the ``input_lag`` nominee alone, or it is dropped: its name
   says the load's physics matter beyond the servo); they are ranked by the change
   of the BIC, the same yardstick for every effect - not by the order they are tried in. With
   lost readings in the estimation data those that lower the BIC by the margin are ranked by
   their validation gap instead (see ``_Run.anchored``): a model without a linear block
   restarts its simulation at the reading after each loss, a cascade cannot, so their
   estimation errors are not alike. The load physics among them take their places in that
   order by the validation misfit of the simulation restarted after each loss
   (:func:`~.prediction.restarted_gap`), when the best of them predicts those runs better
   than the model they augment by what the loop calls a drop (``_Run.predicted``): they all
   restart alike, and a free run of a load that coasts or rings across the play drifts
   whatever the model. An ``input_lag`` fit
   whose lag vanishes is named ``time_delay``: what it adds is a dead time (whole samples
   and a fraction). A physical effect fitted behind a servo's lag the model lacks adds two
   effects in one step, and so does a servo's lag that brings a dead time beyond the model's
   (the lag and ``time_delay``'s dead time): when the best non-physical nominees, each
   followed by its best follow-up, do better (the BIC, or with lost readings the validation
   misfit, as in step 7), the best of them is taken instead (:meth:`_Run.two_in_one`).
5. The best is accepted only if it lowers the BIC by more than a margin *and* lowers the
   validation gap significantly (a one-sided Newey-West test on the squared errors, plus a
   minimum relative drop, and with a measured floor a drop of more than ``floor_margin - 1``
   times it, except for a nominee that re-divides what the model carries and adds no
   parameter: :func:`_redivides`); otherwise the next nominee is checked. With two folds
   (``DiagnoseSettings.folds``, :mod:`.folds`) the drop and its test are judged on the
   squared errors of both held-out blocks pooled: the validation segment at the record's end
   and a block as long at its start, the models refitted on the rest.
6. When none passes alone, the best two nominees are tried with the best follow-up each, as a
   pair against the current model: two effects can hide each other (an offset pins a dead-zone
   constant and the lag then fits badly; the offset alone extrapolates poorly). If no pair
   passes either, stop.
7. When the accepted effect and a rival are nearly tied (the rival's BIC change within
   ``_TIE`` of it, and with lost readings also the validation misfit it closes, between
   two load physics ranked by the restarted misfit that one: a servo lag before the
   backlash and a load lag after it look alike when a dead time hides where the lag sits),
   each is followed by its best follow-up and the path with the lower BIC is
   taken, the numbers in the evidence. (With lost readings, two models that both restart
   their simulation after a loss, or both cannot, are told apart by the BIC alone; a model
   that restarts and one that cannot, whose validation misfits are within ``min_gap_drop``
   of each other, or within ``floor_margin - 1`` times the floor, by the number of free
   parameters: neither BIC is a yardstick for the other.)
8. At the end, with two effects or more, each must earn its place: the final model is refitted
   without it, and an effect whose removal does not worsen the model (the same BIC margin
   and significant validation-gap test as when it was added) is dropped, its step removed
   -- except an ``input_lag`` step whose dead time stays in the refitted model: it is named
   ``time_delay`` and judged in turn.
9. Before each round the gap is compared with the floor quantisation and noise allow
   (:mod:`.floor`): within ``floor_margin`` of it there is nothing left to explain.

Lost readings (``breaks``, the sample rule of :mod:`genbacklash_core.samples`): the
estimation segment keeps its part of the breaks, and every fit there takes them -- the
paper's identification forms no row across a break, the output-error fits restart the
simulation of a backlash at the reading after one (:mod:`.fit`), the residual the detectors
read is that simulation's. The validation gap simulates on through the whole record (a free
run, as the contract says), lost readings included.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from genbacklash_core._typing import ArrayLike, BoolArray, FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.data import NonFinitePolicy, check_excitation
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.identify import identify_backlash, identify_cascade
from genbacklash_core.identify.fitting import prepare_inputs
from genbacklash_core.identify.regression import detect_sign
from genbacklash_core.structure import as_order

from .context import Context, build_context
from .effects import CATALOG, Detection, Effect
from .effects.input_lag import adds_dead_time, vanished
from .fit import ModelFit, fit_model
from .floor import noise_floor
from .folds import FoldErrors, Folds
from .gap import GapReport, Split, measure_gap, split_record
from .model import AugmentedModel, without_effect
from .prediction import restarted_gap
from .result import Diagnosis, DiagnosisStep, Round, Trial
from .settings import DiagnoseSettings
from .spec import anchors_of
from .stats import long_run_variance

__all__ = ["StartStructure", "diagnose", "gap_drop_test", "loss_drop_test"]

_LOOK_AHEAD = 2  # nominees (and follow-ups of each) tried as pairs when none passes alone
_TIE = 0.9  # a rival whose BIC change is at least this share of the best's is a near tie
_SIGN_LAGS = 10  # lags of the input-output covariance that decide the branch sense


@dataclass(frozen=True)
class StartStructure:
    """A starting structure to identify: branch degree and linear orders (``na = 0``: none).

    Examples
    --------
    >>> StartStructure(degree=3).degree
    3
    >>> StartStructure(na=0, nb=1)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: a linear block needs na >= 1 (got na=0, nb=1)
    """

    degree: int = 1
    na: int = 0
    nb: int = 0

    def __post_init__(self) -> None:
        for name in ("degree", "na", "nb"):
            object.__setattr__(self, name, as_order(name, getattr(self, name)))
        if self.degree < 1:
            raise GenBacklashError(f"degree must be >= 1, got {self.degree}")
        if self.na < 0 or self.nb < 0:
            raise GenBacklashError(f"na and nb must be >= 0, got na={self.na}, nb={self.nb}")
        if self.na == 0 and self.nb > 0:
            raise GenBacklashError(f"a linear block needs na >= 1 (got na={self.na}, nb={self.nb})")


Start = AugmentedModel | GeneralBacklash | Cascade | StartStructure | None


def _plain_start(u: FloatArray, y: FloatArray, degree: int, sign: float) -> AugmentedModel:
    """A straight-line start: the least-squares slope of y on u (its size), dead zones 5% of
    the span."""
    uc = u - np.mean(u)
    slope = abs(float(uc @ (y - np.mean(y))) / float(uc @ uc))
    slope = sign * (slope if np.isfinite(slope) and slope > 0.0 else 1.0)
    c = 0.05 * float(np.ptp(u))
    m = (slope, *([0.0] * (degree - 1)))
    return AugmentedModel(GeneralBacklash(m, c, m, c))


def _start_fit(
    start: Start, u: FloatArray, y: FloatArray, breaks: BoolArray | None = None
) -> ModelFit:
    if start is None:
        start = StartStructure()
    if isinstance(start, StartStructure):
        if start.na:
            result = identify_cascade(u, y, start.degree, start.na, start.nb, breaks=breaks)
            return fit_model(AugmentedModel(result.model), u, y, breaks=breaks)
        # The branch sense from the input-output covariance over a few lags: with a lag or a
        # dead time the output follows the input late, and lag 0 alone can get it wrong.
        sign = detect_sign(u, y, _SIGN_LAGS)
        # The paper's iteration can settle on a degenerate model when the data hold effects
        # the start lacks (a long dead time, a slow lag); a plain straight-line start guards.
        result = identify_backlash(u, y, start.degree, sign=sign, breaks=breaks)
        fits = [fit_model(AugmentedModel(result.model), u, y, breaks=breaks)]
        fits.append(fit_model(_plain_start(u, y, start.degree, sign), u, y, breaks=breaks))
        return min(fits, key=lambda fit: fit.sse)
    if isinstance(start, AugmentedModel):
        model = start
    elif isinstance(start, (GeneralBacklash, Cascade)):
        model = AugmentedModel(start)
    else:
        raise GenBacklashError(
            "start must be an AugmentedModel, GeneralBacklash, Cascade, StartStructure or None, "
            f"got {type(start).__name__}"
        )
    try:
        return fit_model(model, u, y, breaks=breaks)
    except GenBacklashError as err:
        raise GenBacklashError(f"the starting model does not fit the data: {err}") from err


def gap_drop_test(y: FloatArray, before: FloatArray, after: FloatArray) -> tuple[float, float]:
    """One-sided test that ``after`` simulates ``y`` better than ``before``.

    The loss difference ``d_t = (y - before)^2 - (y - after)^2`` is tested for a positive mean
    with a Newey-West variance (a Diebold-Mariano test). Returns ``(t, p)``.

    >>> y = np.zeros(200); rng = np.random.default_rng(0)
    >>> t, p = gap_drop_test(y, rng.normal(0, 2, 200), rng.normal(0, 1, 200))
    >>> p < 0.01
    True
    """
    return loss_drop_test((y - before) ** 2 - (y - after) ** 2)


def loss_drop_test(d: FloatArray) -> tuple[float, float]:
    """One-sided test that the loss differences ``d`` (the squared errors before, less
    those after) have a positive mean, with a Newey-West variance; ``(t, p)``."""
    from scipy import stats  # here: a slow import most runs never need

    lrv = long_run_variance(d)
    if lrv <= 0.0:
        return (math.inf, 0.0) if np.mean(d) > 0 else (0.0, 1.0)
    t = float(np.mean(d)) / math.sqrt(lrv / d.size)
    return t, float(stats.norm.sf(t))


def _pooled(
    report: GapReport, candidate: GapReport, folds: Folds | None
) -> tuple[FoldErrors, FoldErrors] | None:
    """Both held-out blocks' errors of the two reports' models (:mod:`.folds`), or None:
    one fold (``folds`` None), or a model not recorded or not refitted on the first block."""
    if folds is None or report.model is None or candidate.model is None:
        return None
    val = report.split.validation
    return folds.errors((report.model, candidate.model), (report.y_sim[val], candidate.y_sim[val]))


def _judge(
    y_val: FloatArray,
    report: GapReport,
    candidate: GapReport,
    bic_change: float,
    settings: DiagnoseSettings,
    floor: float | None = None,
    slack: bool = True,
    folds: Folds | None = None,
) -> tuple[bool, str]:
    val = report.split.validation
    before, after = report.gap, candidate.gap
    pooled = _pooled(report, candidate, folds)
    if pooled is None:
        t, p = gap_drop_test(y_val, report.y_sim[val], candidate.y_sim[val])
        what = "validation misfit"
    else:
        # blocked cross-validation (folds.py): both held-out blocks' errors, one series
        fold_before, fold_after = pooled
        t, p = loss_drop_test(fold_before.squared_errors - fold_after.squared_errors)
        before, after = fold_before.pooled_gap(), fold_after.pooled_gap()
        floor = None if floor is None or folds is None else folds.floor_gap(floor)
        what = "validation misfit over both held-out blocks"
    drop, least, excess = _drop(before, after, settings, floor)
    numbers = (
        f"BIC {bic_change:+.1f} on the estimation data, {what} {before:.4f} -> "
        f"{after:.4f} ({-100 * drop:+.1f}%{excess}, one-sided test t = {t:.1f}, "
        f"p = {p:.2g})"
    )
    if bic_change > -settings.bic_margin:
        return False, f"rejected: the BIC does not drop by {settings.bic_margin:g} ({numbers})"
    if drop < least:
        return False, (
            f"rejected: the validation misfit drops less than {100 * least:g}%{excess} ({numbers})"
        )
    margin = settings.floor_margin - 1.0
    if slack and floor is not None and before - after < margin * floor:
        # a misfit within floor_margin times the floor is left unexplained (nothing to
        # name), so a drop under that slack is within what quantisation and noise allow:
        # near the floor a small drop is a large share of a small excess (a periodic error
        # was named on the near-ideal drivetrain with its motor encoder as the input, for
        # 0.0017 -> 0.0015 with the floor at 0.0009)
        return False, (
            f"rejected: the validation misfit drops by less than {margin:g} times the floor "
            f"{floor:.4f} ({numbers})"
        )
    if p >= settings.gap_alpha:
        return False, f"rejected: the misfit drop is not significant ({numbers})"
    return True, f"accepted: {numbers}"


def _drop(
    before: float, after: float, settings: DiagnoseSettings, floor: float | None
) -> tuple[float, float, str]:
    """The share of the misfit ``before`` that ``after`` closes, the least share the loop
    calls a drop, and the words for what it is a share of: with a measured ``floor`` below
    ``before``, of the excess over it (what quantisation and noise allow; the least then
    ``min_excess_drop``), else of the whole misfit (``min_gap_drop``).

    >>> _drop(0.02, 0.015, DiagnoseSettings(), None)
    (0.25, 0.05, '')
    >>> drop, least, words = _drop(0.02, 0.015, DiagnoseSettings(), 0.01)
    >>> round(drop, 9), least, words
    (0.5, 0.1, ' of the excess over the floor 0.0100')
    """
    if floor is not None and before > floor:
        words = f" of the excess over the floor {floor:.4f}"
        return (before - after) / (before - floor), settings.min_excess_drop, words
    return (1.0 - after / before if before > 0 else 0.0), settings.min_gap_drop, ""


@dataclass(frozen=True)
class _Predicted:
    """The validation misfits restarted after each loss (:func:`~.prediction.restarted_gap`)
    that ranked a round's load physics: the current model's (``before``) and theirs, by
    ``id`` of the candidate (internal)."""

    before: float
    misfit: dict[int, float]


def _ranked_by(predicted: _Predicted | None, *candidates: _Candidate) -> bool:
    """True when ``predicted`` ranked every one of ``candidates`` (all load physics)."""
    return predicted is not None and all(id(c) in predicted.misfit for c in candidates)


@dataclass(frozen=True, eq=False)
class _Candidate:
    """A nominated effect's augmentation, fitted (internal)."""

    detection: Detection
    fit: ModelFit
    bic_change: float

    @property
    def effect(self) -> str:
        return self.detection.effect


def _dead_time_named(candidate: _Candidate) -> _Candidate:
    """``candidate`` named ``time_delay`` when it is ``input_lag``'s fit with a lag that
    vanishes (:func:`~.effects.input_lag.vanished`): what it adds is a dead time (of whole
    samples and a fraction, the fraction carried by the servo's interpolation); else as is.

    On an operation record with curved branches and a dead time of 3.8 ms, the servo's "lag"
    (pole 3e-9) with 3.25 samples of dead time fitted closer than whole samples and was named
    ``input_lag``, and no dead time was named.
    """
    model = candidate.fit.model
    found = candidate.detection
    if found.effect != "input_lag" or not vanished(model):
        return candidate
    evidence = (
        f"{found.evidence}; the servo's lag fitted to nothing (pole {model.input_lag:.2g}): the "
        f"fit adds a dead time of {model.delay + model.input_lag_fraction:g} samples"
    )
    named = replace(found, effect="time_delay", evidence=evidence)
    return _Candidate(named, candidate.fit, candidate.bic_change)


def _redivides(current: ModelFit, candidate: _Candidate) -> bool:
    """True when ``candidate`` names an effect whose structure ``current`` already carries
    and adds no free parameter: it re-divides what the model has (a servo's dead time between
    whole samples and lag stages, :meth:`~.effects.time_delay.TimeDelay.applicable`).

    Such a candidate is judged without the floor's slack (:func:`_judge`): the slack keeps
    parameters from being added for a drop within what quantisation and noise allow, and none
    is added. (A dead time of 4.9 ms behind a servo lag of 14 ms: the servo's step took two
    samples and a second lag stage; five samples and one stage lowered the BIC by 2879 and
    the validation misfit from 0.00108 to 0.00094, t = 15.5, with the floor at 0.00061.)
    """
    return candidate.effect in current.model.effects and candidate.fit.n_free <= current.n_free


def _two_effects(model: AugmentedModel, candidate: _Candidate) -> bool:
    """True when ``candidate``'s step adds two effects of the catalog to ``model`` at once:
    a physical effect fitted behind a servo's lag that ``model`` lacks (the lag and the
    load's physics), or ``input_lag`` with a dead time beyond ``model``'s (the lag and
    ``time_delay``'s dead time, :func:`~.effects.input_lag.adds_dead_time`).

    The second: on an operation record with a load lag of 4.9 ms after the play and a dead
    time of 3.6 ms, a servo's lag with 3.25 samples of dead time (validation misfit 0.00158)
    was taken before the lag after the play alone (0.00193: one effect's misfit is no match
    for two), then the dead time (0.00147); the lag after the play followed by the dead time
    leaves 0.00140.
    """
    fitted = candidate.fit.model
    if fitted.physics is not None:
        return fitted.input_lag != 0.0 and model.input_lag == 0.0
    return candidate.effect == "input_lag" and adds_dead_time(model, fitted)


@dataclass(frozen=True, eq=False)
class _Run:
    """The record and options one diagnosis works on (internal)."""

    u: FloatArray
    y: FloatArray
    split: Split
    effects: tuple[Effect, ...]
    settings: DiagnoseSettings
    breaks: BoolArray | None = None  # of the estimation segment
    floor: float | None = None  # the floor's gap, when the dwells measured the noise
    record_breaks: BoolArray | None = None  # of the whole record
    folds: Folds | None = None  # the second held-out block, with two folds

    def nominate(
        self, context: Context
    ) -> tuple[tuple[Detection, ...], list[_Candidate], list[Trial]]:
        """Run the detectors, fit the nominees' augmentations, rank them by the BIC change."""
        current = context.fit
        detections = tuple(
            effect.detect(context) for effect in self.effects if effect.applicable(current.model)
        )
        by_name = {effect.name: effect for effect in self.effects}
        candidates: list[_Candidate] = []
        failed: list[Trial] = []
        for found in detections:
            if not found.fires:
                continue
            augmented = by_name[found.effect].augment(context, found)
            if augmented is None:
                failed.append(Trial(found.effect, math.nan, None, False, "no valid fit"))
                continue
            candidates.append(_Candidate(found, augmented, augmented.bic - current.bic))
        candidates.sort(key=lambda c: c.bic_change)
        candidates, behind = self.beyond_servo(current.model, candidates)
        # after beyond_servo, which judges the physics fitted behind a servo lag against it
        candidates = [_dead_time_named(c) for c in candidates]
        return detections, candidates, failed + behind

    def beyond_servo(
        self, model: AugmentedModel, candidates: list[_Candidate]
    ) -> tuple[list[_Candidate], list[Trial]]:
        """Drop the physical effects fitted behind a servo's lag (which ``model`` lacks) that
        do not pass the acceptance test against that lag alone (the ``input_lag`` nominee):
        their name says the load's physics matter, so the physics must explain more than the
        servo does -- not only the servo, with a few more parameters to spare."""
        lag = next((c for c in candidates if c.effect == "input_lag"), None)
        if lag is None or model.input_lag != 0.0:
            return candidates, []
        kept: list[_Candidate] = []
        dropped: list[Trial] = []
        lag_report: GapReport | None = None
        for candidate in candidates:
            fitted = candidate.fit.model
            if fitted.physics is None or fitted.input_lag == 0.0:
                kept.append(candidate)
                continue
            if lag_report is None:
                lag_report = measure_gap(lag.fit.model, self.u, self.y, self.split)
            after = measure_gap(fitted, self.u, self.y, self.split)
            ok, verdict = self.judge(lag_report, after, candidate.fit.bic - lag.fit.bic)
            if ok:
                kept.append(candidate)
                continue
            dropped.append(
                Trial(
                    candidate.effect,
                    candidate.bic_change,
                    after.gap,
                    False,
                    f"fitted behind the servo's lag, against that lag alone (input_lag): {verdict}",
                )
            )
        return kept, dropped

    def judge(
        self, before: GapReport, after: GapReport, bic_change: float, slack: bool = True
    ) -> tuple[bool, str]:
        """Accept an augmentation? (BIC margin, validation gap drop, its significance; with
        ``slack``, a drop of more than ``floor_margin - 1`` times the floor)."""
        return _judge(
            self.y[self.split.validation],
            before,
            after,
            bic_change,
            self.settings,
            self.floor,
            slack,
            self.folds,
        )

    @property
    def anchored(self) -> bool:
        """True when the estimation data have lost readings: then the fits of models that
        restart their simulation at the reading after a loss and of models that cannot (a
        linear block's state is not one reading) are not comparable by their estimation
        error, and candidates are ranked by the free-run validation gap instead."""
        return anchors_of(self.breaks) is not None

    def rank_by_gap(
        self, candidates: list[_Candidate], model: AugmentedModel
    ) -> tuple[list[_Candidate], dict[int, GapReport], _Predicted | None]:
        """The candidates that lower the BIC by the margin, by their validation gap (lowest
        first; the load physics among their own places as :meth:`physics_by_prediction`
        orders them from ``model``, the current model), then the others; their gap reports
        (by ``id``); and the restarted misfits that ordered the load physics, if any."""
        margin = self.settings.bic_margin
        good = [c for c in candidates if c.bic_change < -margin]
        gaps = {id(c): measure_gap(c.fit.model, self.u, self.y, self.split) for c in good}
        good.sort(key=lambda c: gaps[id(c)].gap)
        ranked, predicted = self.physics_by_prediction(good, model)
        return ranked + [c for c in candidates if c.bic_change >= -margin], gaps, predicted

    def physics_by_prediction(
        self, ranked: list[_Candidate], model: AugmentedModel
    ) -> tuple[list[_Candidate], _Predicted | None]:
        """``ranked`` with its load physics reordered among their own places by the
        validation misfit of the simulation restarted after each loss
        (:func:`~.prediction.restarted_gap`), the others where they are, when that misfit
        tells them from ``model``, the model they augment (:meth:`predicted`); and those
        misfits (None: ``ranked`` as it is).

        The load physics all restart at a reading as the fits do, and a load that coasts or
        rings across the play is chaotic in a free run, which drifts whatever the model: on
        the compliant physics drivetrain behind a 100 Hz servo the spring predicted the
        restarted validation runs better than the coasting load (NRMSE 0.013 against 0.016,
        its BIC 16000 lower) and drifted further in the free run (0.046 against 0.032), which
        had named the coasting load.
        """
        places = [i for i, c in enumerate(ranked) if c.fit.model.physics is not None]
        predicted = self.predicted(model, [ranked[i] for i in places])
        if predicted is None:
            return ranked, None
        physics = sorted((ranked[i] for i in places), key=lambda c: predicted.misfit[id(c)])
        out = list(ranked)
        for i, c in zip(places, physics, strict=True):
            out[i] = c
        return out, predicted

    def predicted(self, model: AugmentedModel, physics: list[_Candidate]) -> _Predicted | None:
        """The restarted validation misfits (:func:`~.prediction.restarted_gap`) of two or
        more load physics candidates and of ``model``, which they augment, when the best of
        them lowers ``model``'s by what the loop calls a drop (:func:`_drop`); else None.

        Between two losses (2 % of the readings: some 50 samples) a restarted run sees
        where a ringing spring or a coasting load goes next, but not always a flank held
        across a reversal: where no load physics predicts those runs measurably better than
        the model it augments, that misfit tells them from nothing and does not rank them
        (nor break their near ties), and the free run does, as every other candidate. (On
        the gravity drivetrain behind a 60 Hz servo, 30 s, seed 0, the restarted misfits
        were 0.0107-0.0122 against the plain backlash's 0.0116, the floor 0.00056: the
        coasting load was ranked before the load torque, whose free run 0.0175 was the best
        and BIC 8500 lower. On the compliant one behind a 100 Hz servo, seed 1, the spring
        took 0.0279 to 0.0129.)
        """
        breaks = self.record_breaks
        if len(physics) < 2 or breaks is None or model.cascade:
            return None
        misfit = {
            id(c): restarted_gap(c.fit.model, self.u, self.y, self.split, breaks) for c in physics
        }
        before = restarted_gap(model, self.u, self.y, self.split, breaks)
        drop, least, _ = _drop(before, min(misfit.values()), self.settings, self.floor)
        return _Predicted(before, misfit) if drop >= least else None

    def misfits(self, *models: AugmentedModel, restarted: bool) -> tuple[list[float], str]:
        """The validation misfits of ``models`` on one yardstick, and its name: with
        ``restarted`` (the yardstick that ranked two load physics tied, :meth:`predicted`),
        and when every model has load physics and no linear block, the misfit of the
        simulation restarted after each loss (:func:`~.prediction.restarted_gap`); else
        the free-run validation gap (:func:`~.gap.measure_gap`).

        One yardstick ranks the load physics and breaks their near ties, down to the paths
        of their follow-ups. (On the gravity drivetrain behind a 60 Hz servo, 4 s, seed 0,
        the load torque's restarted misfit 0.0723 ranked it before the spring's 0.1185;
        their free-run misfits, 0.1226 and 0.1187, called it a near tie, and the spring's
        BIC took it.)
        """
        breaks = self.record_breaks
        if restarted and breaks is not None:
            if all(m.physics is not None and not m.cascade for m in models):
                values = [restarted_gap(m, self.u, self.y, self.split, breaks) for m in models]
                return values, "validation misfit restarted after each loss"
        return [measure_gap(m, self.u, self.y, self.split).gap for m in models], "validation misfit"

    def follow_up(self, first: _Candidate) -> tuple[ModelFit, str]:
        """The fit after ``first`` and its best follow-up (``first``'s own when none lowers
        the BIC by the margin), and that follow-up's name ("nothing")."""
        est = self.split.estimation
        context = build_context(self.u[est], self.y[est], first.fit, self.settings, self.breaks)
        _, seconds, _ = self.nominate(context)
        seconds = [c for c in seconds if c.bic_change < -self.settings.bic_margin]
        if self.anchored and seconds:
            seconds, _, _ = self.rank_by_gap(seconds, first.fit.model)
        return (seconds[0].fit, seconds[0].effect) if seconds else (first.fit, "nothing")

    def break_tie(
        self,
        report: GapReport,
        candidates: list[_Candidate],
        chosen: _Candidate,
        gaps: dict[int, GapReport] | None = None,
        predicted: _Predicted | None = None,
    ) -> tuple[_Candidate, GapReport, str] | None:
        """A rival nearly tied with ``chosen`` (see the module notes, step 7) that wins once
        both are followed by their best follow-up, judged as ``chosen`` was; else None.

        A near tie is measured on the yardstick that ranked the candidates: the BIC change,
        or, when ``anchored`` (``gaps``: the candidates' validation gaps), the validation
        misfit each closes, and between two load physics that ``predicted`` ranked, the
        misfit restarted after each loss (:meth:`ties`), as are their paths. A rival that
        closes far less of the misfit is no tie, however close its BIC (which the ranking
        did not trust): a dead time closing 21 % of a coasting load's misfit was preferred to
        the coasting load closing 37 % by the follow-ups, before this rule.
        """
        margin = self.settings.bic_margin
        rivals = [
            c
            for c in candidates
            if c is not chosen
            and c.bic_change < -margin
            and c.bic_change <= _TIE * chosen.bic_change
        ]
        if self.anchored and gaps is not None and id(chosen) in gaps:
            rivals = [
                c for c in rivals if id(c) in gaps and self.ties(report, chosen, c, gaps, predicted)
            ]
        if not rivals:
            return None
        alike = [
            c
            for c in rivals
            if c.fit.model.cascade == chosen.fit.model.cascade
            and c.bic_change < chosen.bic_change - margin
        ]
        if self.anchored and alike:
            # Tied on the validation misfit, and both restart their simulation after a loss
            # (or neither does): their estimation errors are alike, and the BIC on the
            # larger estimation segment, which counts the parameters, decides. (A spring
            # after the play fitted the near-ideal drivetrain's critically damped servo 4 %
            # closer on the validation data, with a BIC 5000 worse than the servo's lag.)
            best = min(alike, key=lambda c: c.bic_change)
            after = gaps.get(id(best)) if gaps is not None else None
            after = after or measure_gap(best.fit.model, self.u, self.y, self.split)
            ok, verdict = self.judge(report, after, best.bic_change)
            if ok:
                mine = gaps[id(chosen)].gap if gaps is not None else math.nan
                note = (
                    f"{verdict}; preferred to {chosen.effect} (validation misfit {mine:.4f}, "
                    f"a near tie): its BIC is {chosen.bic_change - best.bic_change:.1f} lower"
                )
                return best, after, note
        simpler = self.simpler_in_tie(report, rivals, chosen, gaps)
        if simpler is not None:
            return simpler
        rival = rivals[0]
        fit_chosen, next_chosen = self.follow_up(chosen)
        fit_rival, next_rival = self.follow_up(rival)
        restarted = _ranked_by(predicted, chosen, rival)
        (gap_rival, gap_chosen), what = self.misfits(
            fit_rival.model, fit_chosen.model, restarted=restarted
        )
        wins, _, better = self.path_beats(
            (fit_rival.bic, gap_rival), (fit_chosen.bic, gap_chosen), what
        )
        accepted = self.rival_accepted(report, rival, gaps) if wins else None
        if accepted is None:
            return None
        after, verdict = accepted
        note = (
            f"{verdict}; preferred to {chosen.effect} (BIC {chosen.bic_change:+.1f} alone, a "
            f"near tie): followed by {next_rival} {better} than {chosen.effect} followed by "
            f"{next_chosen}"
        )
        return rival, after, note

    def ties(
        self,
        report: GapReport,
        chosen: _Candidate,
        rival: _Candidate,
        gaps: dict[int, GapReport],
        predicted: _Predicted | None,
    ) -> bool:
        """Does ``rival`` close at least ``_TIE`` of the validation misfit ``chosen`` closes
        from the current model's (its ``report``)? Between two load physics that
        ``predicted`` ranked, the misfit restarted after each loss
        (:meth:`physics_by_prediction`); else the free-run gaps in ``gaps``."""
        if predicted is not None and _ranked_by(predicted, chosen, rival):
            before = predicted.before
            mine, theirs = predicted.misfit[id(chosen)], predicted.misfit[id(rival)]
        else:
            before, mine, theirs = report.gap, gaps[id(chosen)].gap, gaps[id(rival)].gap
        return before - theirs >= _TIE * (before - mine)

    def path_beats(
        self, rival: tuple[float, float], chosen: tuple[float, float], what: str
    ) -> tuple[bool, float, str]:
        """Does a path ending at ``rival`` (its BIC, its validation misfit, ``what``:
        :meth:`misfits`'s name of it) beat one ending at ``chosen``? With lost readings by
        the validation misfit, ``min_gap_drop`` lower (see :attr:`anchored`), else by the
        BIC, the margin lower. Also the yardstick's value for ``rival`` and the comparison
        in words."""
        (bic_rival, gap_rival), (bic_chosen, gap_chosen) = rival, chosen
        if self.anchored:
            return (
                gap_rival < (1.0 - self.settings.min_gap_drop) * gap_chosen,
                gap_rival,
                f"its {what} {gap_rival:.4f} is lower than {gap_chosen:.4f}",
            )
        return (
            bic_rival < bic_chosen - self.settings.bic_margin,
            bic_rival,
            f"the model's BIC is {bic_chosen - bic_rival:.1f} lower",
        )

    def rival_accepted(
        self, report: GapReport, rival: _Candidate, gaps: dict[int, GapReport] | None
    ) -> tuple[GapReport, str] | None:
        """``rival``'s gap and the acceptance verdict, when it passes alone; else None."""
        after = (gaps.get(id(rival)) if gaps is not None else None) or measure_gap(
            rival.fit.model, self.u, self.y, self.split
        )
        ok, verdict = self.judge(report, after, rival.bic_change)
        return (after, verdict) if ok else None

    def two_in_one(
        self,
        model: AugmentedModel,
        report: GapReport,
        candidates: list[_Candidate],
        chosen: _Candidate,
        gaps: dict[int, GapReport] | None = None,
    ) -> tuple[_Candidate, GapReport, str] | None:
        """When ``chosen`` adds two effects in one step (:func:`_two_effects`), the best of
        the non-physical rivals that lowers the BIC by the margin once each is followed by its
        best follow-up, when that path beats ``chosen`` as :meth:`break_tie` judges (the
        BIC, or with lost readings the validation misfit); else None. (See the module
        notes, step 4.) A physical ``chosen`` stays when the winning path ends in its own
        effect (the rival, then ``chosen``'s effect) and the path's second step closes more
        of the validation misfit than its first: the effect that dominates is then the
        physical one, which ``chosen`` names first with the servo's lag in the same step.

        Such a step adds two effects at once, with the parameters of both, and the BIC
        change or the misfit of a one-effect rival is no yardstick for it: the rival is
        given its second effect first. On a paper-style record with an output offset and a
        dead time, a load torque behind a servo lag (BIC -8629) was named before the offset
        (-7173), whose path with the dead time explains the record; with a lag after the
        play and an output limit the torque was named before both.
        """
        fitted = chosen.fit.model
        if not _two_effects(model, chosen):
            return None
        margin = self.settings.bic_margin
        rivals = [
            c
            for c in candidates
            if c is not chosen and c.fit.model.physics is None and c.bic_change < -margin
        ][:_LOOK_AHEAD]
        mine = gaps.get(id(chosen)) if gaps is not None else None
        gap_chosen = (mine or measure_gap(fitted, self.u, self.y, self.split)).gap
        best: tuple[float, _Candidate, str, str, float] | None = None
        for rival in rivals:
            fit_rival, next_rival = self.follow_up(rival)
            gap_rival = measure_gap(fit_rival.model, self.u, self.y, self.split).gap
            wins, score, better = self.path_beats(
                (fit_rival.bic, gap_rival), (chosen.fit.bic, gap_chosen), "validation misfit"
            )
            if wins and (best is None or score < best[0]):
                best = (score, rival, next_rival, better, gap_rival)
        accepted = None if best is None else self.rival_accepted(report, best[1], gaps)
        if best is None or accepted is None:
            return None
        _, rival, next_rival, better, gap_path = best
        after, verdict = accepted
        physical = fitted.physics is not None
        if (
            physical
            and next_rival == chosen.effect
            and after.gap - gap_path > report.gap - after.gap
        ):
            # The path ends in ``chosen``'s own physical effect (the rival, then that effect)
            # and its second step closes more of the misfit than its first: the dominant
            # effect is the physical one, which ``chosen`` names first with the servo's lag
            # in the same step. A coasting load behind a 20 Hz servo: the lag alone 0.0584 ->
            # 0.0459, then the coasting load -> 0.0069; the load behind the lag in one step
            # 0.0076. (A path to other effects keeps its win: a lag after the play, then an
            # output limit, against a load torque behind a servo's lag.)
            return None
        how = (
            "fitted behind a servo's lag"
            if physical
            else f"with a dead time of {fitted.delay + fitted.input_lag_fraction:g} samples"
        )
        note = (
            f"{verdict}; preferred to {chosen.effect} {how} (two effects in one step, BIC "
            f"{chosen.bic_change:+.1f}): followed by {next_rival} {better}"
        )
        return rival, after, note

    def simpler_in_tie(
        self,
        report: GapReport,
        rivals: list[_Candidate],
        chosen: _Candidate,
        gaps: dict[int, GapReport] | None,
    ) -> tuple[_Candidate, GapReport, str] | None:
        """With lost readings, a rival with fewer free parameters whose validation misfit is
        within :meth:`tie_band` of ``chosen``'s, when one of the two is a cascade and the
        other is not; else None.

        Such a pair was fitted on different objectives (a cascade cannot restart its
        simulation after a loss), so neither BIC is a yardstick for the other, and the
        validation misfit ranked them by less than the loop calls a drop: the data do not
        tell them apart, and the model with fewer parameters is preferred, as the BIC would
        between two fits alike. (On the near-ideal physics drivetrain the servo's lag before
        the play, 5-6 parameters, and a lag after it, 7, came within 1 % of each other, and
        the lag after was named.)
        """
        if not self.anchored or gaps is None or id(chosen) not in gaps:
            return None
        mine = gaps[id(chosen)].gap
        band, within = self.tie_band(mine)
        simpler = [
            c
            for c in rivals
            if c.fit.model.cascade != chosen.fit.model.cascade
            and id(c) in gaps
            and gaps[id(c)].gap <= mine + band
            and c.fit.n_free < chosen.fit.n_free
        ]
        if not simpler:
            return None
        best = min(simpler, key=lambda c: gaps[id(c)].gap)
        after = gaps[id(best)]
        ok, verdict = self.judge(report, after, best.bic_change)
        if not ok:
            return None
        note = (
            f"{verdict}; preferred to {chosen.effect} (validation misfit {mine:.4f}, within "
            f"{within}, a near tie between a model that restarts after a loss and one that "
            f"cannot): it has {best.fit.n_free} free parameters, {chosen.effect} "
            f"{chosen.fit.n_free}"
        )
        return best, after, note

    def tie_band(self, gap: float) -> tuple[float, str]:
        """How far above ``gap`` a rival's validation misfit may lie and still tie with it,
        and that band in words.

        The larger of two amounts the loop already treats as no difference: ``min_gap_drop``
        of ``gap`` (less than it calls a drop), and, when the dwells measured the floor,
        ``floor_margin - 1`` times the floor (a drop under that is within what quantisation
        and noise allow: :func:`_judge` names nothing for it). Near the floor the second is
        the larger: on the near-ideal physics drivetrain at 20 Hz, seed 2, the lag after the
        play left 0.00090 and the servo's lag 0.00098 (floor 0.00055): 9 % apart, but 0.14
        floors.

        >>> run = _Run(np.zeros(1), np.zeros(1), split_record(200, 0.3), (), DiagnoseSettings(),
        ...            floor=0.001)
        >>> band, words = run.tie_band(0.002)
        >>> round(band, 6), words
        (0.0003, '0.3 times the floor 0.0010')
        >>> band, words = run.tie_band(0.01)
        >>> round(band, 6), words
        (0.0005, '5%')
        """
        settings = self.settings
        relative = settings.min_gap_drop * gap
        if self.floor is None:
            return relative, f"{100 * settings.min_gap_drop:g}%"
        slack = (settings.floor_margin - 1.0) * self.floor
        if slack <= relative:
            return relative, f"{100 * settings.min_gap_drop:g}%"
        return slack, f"{settings.floor_margin - 1.0:g} times the floor {self.floor:.4f}"

    def earns_place(
        self, final: ModelFit, final_report: GapReport, effect: str
    ) -> tuple[ModelFit, GapReport, str] | None:
        """Refit the final model without ``effect``; when that is not significantly worse
        (the acceptance test, reversed), return the refit, its gap and why; else None."""
        reduced = without_effect(final.model, effect)
        if reduced is None:
            return None
        est = self.split.estimation
        try:
            refit = fit_model(reduced, self.u[est], self.y[est], breaks=self.breaks)
        except GenBacklashError:
            return None
        after = measure_gap(refit.model, self.u, self.y, self.split)
        ok, verdict = self.judge(after, final_report, final.bic - refit.bic)
        if ok:
            return None
        return refit, after, f"{effect} does not earn its place next to the others ({verdict})"

    def prune(
        self,
        current: ModelFit,
        report: GapReport,
        steps: list[DiagnosisStep],
        reports: list[GapReport],
        start_delay: int = 0,
    ) -> tuple[ModelFit, GapReport, list[DiagnosisStep], list[GapReport], list[str]]:
        """Drop the steps whose effect does not earn its place next to the others (see the
        module notes, step 8); the final fit, its gap, the steps, their gaps (the start's
        first) and what was done, in words. ``start_delay``: the starting model's dead time.

        ``input_lag`` carries the servo's dead time with its lag: when the lag goes and the
        dead time its step added stays in the refitted model, the step is kept as what is
        left of it, ``time_delay``, which must then earn its place in turn. (A dead time with
        a runout: the servo's lag and dead time were named, then the lag dropped, and the
        model kept a dead time no step named.)
        """
        notes: list[str] = []
        effects = list(dict.fromkeys(step.effect for step in steps))
        for effect in effects:
            if len(steps) < 2:
                break
            pruned = self.earns_place(current, report, effect)
            if pruned is None:
                continue
            current, report, note = pruned
            named = {step.effect for step in steps}
            added = current.model.delay > start_delay and "time_delay" not in named
            if effect == "input_lag" and added:
                # the dead time stays: the steps that added it are named for it
                kept = f"{note}, so it was dropped; the dead time of its step stays (time_delay)"
                steps = [
                    replace(
                        step, effect="time_delay", evidence=f"{step.evidence}; at the end {kept}"
                    )
                    if step.effect == effect
                    else step
                    for step in steps
                ]
                reports[-1] = report
                steps[-1] = replace(steps[-1], gap_after=report.gap, model=current.model)
                notes.append(kept)
                effects.append("time_delay")
                continue
            keep = [i for i, step in enumerate(steps) if step.effect != effect]
            steps = [steps[i] for i in keep]
            reports = [reports[0], *(reports[i + 1] for i in keep)]
            reports[-1] = report
            if steps:
                steps[-1] = replace(
                    steps[-1],
                    evidence=f"{steps[-1].evidence}; at the end {note}, so it was dropped",
                    gap_after=report.gap,
                    model=current.model,
                )
            notes.append(f"{note}, so it was dropped")
        return current, report, steps, reports, notes

    def look_ahead(
        self, report: GapReport, candidates: list[_Candidate], alone: dict[str, str]
    ) -> tuple[list[tuple[_Candidate, GapReport, str]], Round | None]:
        """Two effects may only pay off together (an offset hiding a lag, say): try the best
        nominees with the best follow-up each, judged as a pair against the current model."""
        settings = self.settings
        est = self.split.estimation
        extra: Round | None = None
        firsts = [c for c in candidates if c.bic_change < -settings.bic_margin][:_LOOK_AHEAD]
        for first in firsts:
            first_report = measure_gap(first.fit.model, self.u, self.y, self.split)
            context = build_context(self.u[est], self.y[est], first.fit, settings, self.breaks)
            detections, seconds, trials = self.nominate(context)
            for second in seconds[:_LOOK_AHEAD]:
                if second.bic_change > -settings.bic_margin:
                    continue
                after = measure_gap(second.fit.model, self.u, self.y, self.split)
                total = first.bic_change + second.bic_change
                ok, verdict = self.judge(report, after, total)
                verdict = f"together with {first.effect}, {verdict}"
                trials.append(Trial(second.effect, second.bic_change, after.gap, ok, verdict))
                if ok:
                    note = (
                        f"accepted together with the next step ({second.effect}): alone it was "
                        f"{alone.get(first.effect, 'not judged')}"
                    )
                    extra = Round(first_report.gap, context.analysis, detections, tuple(trials))
                    return [(first, first_report, note), (second, after, verdict)], extra
            extra = Round(first_report.gap, context.analysis, detections, tuple(trials))
        return [], extra


def _quiet(stage: str) -> None:
    """The default progress callback: nothing."""


def diagnose(
    u: ArrayLike,
    y: ArrayLike,
    *,
    start: Start = None,
    settings: DiagnoseSettings | None = None,
    catalog: Sequence[Effect] | None = None,
    nonfinite: NonFinitePolicy = "raise",
    breaks: ArrayLike | None = None,
    progress: Callable[[str], None] | None = None,
) -> Diagnosis:
    """Find where a backlash model and the measurements disagree, name the missing effects and
    add them while the validation gap drops significantly.

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Command and measured position.
    start : AugmentedModel, GeneralBacklash, Cascade or StartStructure, optional
        The starting model (refitted on the estimation segment), or a structure to identify;
        default the ideal backlash of eq. (1) (degree 1, no dynamics).
    settings : DiagnoseSettings, optional
        Validation fraction and thresholds.
    catalog : sequence of Effect, optional
        The effects to consider; default :data:`~genbacklash_core.diagnose.effects.CATALOG`.
    nonfinite : {"raise", "drop"}
        Policy for NaN/inf samples.
    breaks : array_like of bool, shape (N,), optional
        The sample rule (:func:`~genbacklash_core.samples.sample_breaks`): True where a
        sample does not follow the one before it on the encoder's clock (a lost reading, a
        gap); see the module notes. Default: all consecutive.

    Returns
    -------
    Diagnosis

    Raises
    ------
    NonFiniteInputError, NotEnoughExcitationError, GenBacklashError

    Examples
    --------
    >>> from genbacklash_core.diagnose.synthetic import synthetic_case
    >>> case = synthetic_case(["time_delay"], seed=1, n_samples=1500)
    >>> result = diagnose(case.u, case.y)
    >>> result.effects, result.model.delay == case.truth.delay
    (('time_delay',), True)
    >>> result.gap_final < 0.5 * result.gap_initial
    True
    """
    settings = DiagnoseSettings() if settings is None else settings
    stage = progress if progress is not None else _quiet
    effects = tuple(CATALOG if catalog is None else catalog)
    uu, yy, bb = prepare_inputs(u, y, nonfinite, breaks)  # a dropped sample breaks the chain
    split = split_record(uu.size, settings.validation)
    u_est, y_est = uu[split.estimation], yy[split.estimation]
    b_est = None if bb is None else bb[split.estimation]
    check_excitation(u_est, y_est, 4)
    stage("measuring the noise floor")
    floor = noise_floor(uu, yy, split.validation, bb)
    folds = Folds(uu, yy, split, bb) if settings.folds == 2 else None
    run = _Run(
        uu, yy, split, effects, settings, b_est, floor.gap if floor.known else None, bb, folds
    )

    stage("fitting the starting model")
    current = _start_fit(start, u_est, y_est, b_est)
    initial = current
    report = measure_gap(current.model, uu, yy, split)
    reports = [report]
    steps: list[DiagnosisStep] = []
    rounds: list[Round] = []
    reason = f"stopped after the step limit ({settings.max_steps})"
    while True:
        stage(f"round {len(rounds) + 1}: residual tests and detectors")
        context = build_context(u_est, y_est, current, settings, b_est)
        analysis = context.analysis
        if floor.known and report.gap <= settings.floor_margin * floor.gap:
            rounds.append(Round(report.gap, analysis, (), ()))
            reason = (
                f"the misfit {report.gap:.4f} is within {settings.floor_margin:g} times the floor: "
                f"{floor.describe()}; nothing is left for an effect to explain"
            )
            break
        noise = analysis.consistent_with_noise(settings.alpha)
        tests = (
            f"Ljung-Box p = {analysis.ljung_box.p_value:.2g}, input cross-correlation "
            f"p = {analysis.cross_portmanteau.p_value:.2g}"
        )
        if len(steps) >= settings.max_steps:
            rounds.append(Round(report.gap, analysis, (), ()))
            break
        detections, candidates, trials = run.nominate(context)
        if not candidates and not trials:
            rounds.append(Round(report.gap, analysis, detections, ()))
            reason = (
                f"the residual is consistent with noise ({tests}, no higher-order structure) "
                "and no detector finds its signature"
                if noise
                else f"the residual is not consistent with noise ({tests}) but no detector in "
                "the catalog recognises its signature"
            )
            break
        stage(f"round {len(rounds) + 1}: judging {len(candidates)} candidate effects")
        accepted: list[tuple[_Candidate, GapReport, str]] = []
        alone: dict[str, str] = {}
        gaps: dict[int, GapReport] = {}
        predicted: _Predicted | None = None
        if run.anchored:
            candidates, gaps, predicted = run.rank_by_gap(candidates, current.model)
        for candidate in candidates:
            if accepted:
                trials.append(
                    Trial(candidate.effect, candidate.bic_change, None, False, "not needed")
                )
                continue
            after = gaps.get(id(candidate)) or measure_gap(candidate.fit.model, uu, yy, split)
            ok, verdict = run.judge(
                report, after, candidate.bic_change, not _redivides(current, candidate)
            )
            trials.append(Trial(candidate.effect, candidate.bic_change, after.gap, ok, verdict))
            alone[candidate.effect] = verdict
            if ok:
                accepted = [(candidate, after, verdict)]
        if len(accepted) == 1:
            swapped = run.two_in_one(current.model, report, candidates, accepted[0][0], gaps)
            swapped = swapped or run.break_tie(report, candidates, accepted[0][0], gaps, predicted)
            if swapped is not None:
                trials.append(
                    Trial(
                        swapped[0].effect, swapped[0].bic_change, swapped[1].gap, True, swapped[2]
                    )
                )
                accepted = [swapped]
        rounds.append(Round(report.gap, analysis, detections, tuple(trials)))
        if not accepted and len(steps) + 2 <= settings.max_steps:
            stage(f"round {len(rounds)}: trying pairs of effects")
            accepted, extra = run.look_ahead(report, candidates, alone)
            if extra is not None:
                rounds.append(extra)
        if not accepted:
            names = ", ".join(c.effect for c in candidates) or "none fitted"
            reason = (
                f"no nominated effect ({names}) improves the model significantly on both the "
                f"estimation and the validation data ({tests})"
            )
            break
        for candidate, after, verdict in accepted:
            dropped = [e for e in current.model.effects if e not in candidate.fit.model.effects]
            note = f" (it replaces {', '.join(dropped)}, which it explains)" if dropped else ""
            steps.append(
                DiagnosisStep(
                    candidate.effect,
                    f"{candidate.detection.evidence}; {verdict}{note}",
                    report.gap,
                    after.gap,
                    candidate.bic_change,
                    candidate.fit.model,
                )
            )
            current, report = candidate.fit, after
            reports.append(report)
    if len(steps) >= 2:
        stage("checking that each effect earns its place")
        current, report, steps, reports, notes = run.prune(
            current, report, steps, reports, initial.model.delay
        )
        reason += "".join(f"; {note}" for note in notes)
    return Diagnosis(
        steps=tuple(steps),
        gap_initial=reports[0].gap,
        gap_final=report.gap,
        model=current.model,
        fit=current,
        initial_fit=initial,
        split=split,
        reports=tuple(reports),
        rounds=tuple(rounds),
        reason=reason,
        floor=floor,
    )
