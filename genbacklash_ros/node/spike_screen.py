"""The spike screen: which encoder samples to feed the identifier, judged by the model.

Once the estimate of a general backlash has converged and a residual scale is known, each
sample fed is predicted from the one before it by the clamp of eq. (20); a reading more
than ``SPIKE_SIGMAS`` residual scales (and ``SPIKE_COUNTS`` encoder counts) from its
prediction that the reading after it does not follow is a spike, not fed (``encoder_spike``
drops); samples after a gap wait, ``RESYNC_NS`` at most, for one consistent with the sample
before it (``encoder_after_gap``). The rules, their thresholds and the records behind them
are in the notes of :mod:`genbacklash_ros.node.health`, whose
:class:`~genbacklash_ros.node.health.StreamHealth` holds a :class:`SpikeScreen` and hands it
each feed (:meth:`~genbacklash_ros.node.health.StreamHealth.screen`); its stuck-encoder check
reads the screen's residual scale.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from genbacklash_core import Estimate, EstimatorState, GeneralBacklash
from genbacklash_ros.node.health_events import Drop, HealthEvent

__all__ = [
    "RESYNC_NS",
    "SCREEN_SAMPLES",
    "SHIFT_PLAY_SHARE",
    "SPIKE_COUNTS",
    "SPIKE_MAX_SHARE",
    "SPIKE_SIGMAS",
    "Screening",
    "SpikeScreen",
    "exact_median",
]

SPIKE_SIGMAS = 8.0  # a reading this many residual scales from its prediction is a spike
SPIKE_MAX_SHARE = 0.2  # more of a step than this: the model is off, not the encoder
SCREEN_SAMPLES = 64  # samples the screen judges with one residual scale (it follows each step)
SPIKE_COUNTS = 2.0  # ... and at least this many encoder counts (a quantised reading's error)
RESYNC_NS = 500_000_000  # after a gap, samples wait this long at most for a consistent one
_SCALE_SMOOTHING = 0.2  # weight of a new step in the residual scale
# the band's edges as the readings show them (see StreamHealth.screen): a step's median offset
# of the readings pushed by an edge is blended in with this weight, from this many readings
_SHIFT_SMOOTHING = 0.3
_SHIFT_MIN_READINGS = 3
SHIFT_PLAY_SHARE = 0.25  # an edge is moved by at most this share of the play c_L + c_R


class Screening(NamedTuple):
    """What :meth:`SpikeScreen.screen` made of a batch of samples.

    Attributes
    ----------
    keep : numpy.ndarray of bool or None
        The samples to feed (None: all of them).
    events : list of Drop or Note
        The spikes and the samples held back after a gap, counted as drops.
    """

    keep: np.ndarray | None
    events: list[HealthEvent]


def exact_median(values: np.ndarray) -> float:
    """``np.median`` of a non-empty 1-D array, to the bit (the middle value, or the mean of
    the two middle ones), from one partition and without its generic machinery.

    >>> exact_median(np.array([3.0, 1.0, 2.0, 10.0]))
    2.5
    """
    n = values.size
    half = n // 2
    if n % 2:
        return float(np.partition(values, half)[half])
    ordered = np.partition(values, (half - 1, half))
    return (float(ordered[half - 1]) + float(ordered[half])) / 2.0


def _one_step_errors(
    y_prev: float,
    band_prev: tuple[float, float],
    ys: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    resumed: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The one-step errors of eq. (20)'s clamp: each reading ``ys`` (band ``low .. high``)
    predicted from the one before it (the first from ``y_prev``, its band ``band_prev``),
    the clamp moving the part of it inside its band and keeping the offset outside it (a
    band that lags the drivetrain by an offset lags it by as much one reading later). A
    ``resumed`` reading (after samples taken out while the servo settled: the commands
    between may have reversed) is judged by the band alone, ``|y - clamp(y, low, high)|``.

    Returns the errors and which readings the clamp put on the band's lower and upper edge
    (the load pushed by a flank)."""
    n = ys.size
    previous, low_prev, high_prev = np.empty(n), np.empty(n), np.empty(n)
    if n:  # each shifted by one, the one before first
        previous[0], previous[1:] = y_prev, ys[:-1]
        low_prev[0], low_prev[1:] = band_prev[0], low[:-1]
        high_prev[0], high_prev[1:] = band_prev[1], high[:-1]
    with np.errstate(all="ignore"):
        inside = np.minimum(np.maximum(previous, low_prev), high_prev)
        carry = previous - inside
        if resumed is not None:
            inside[resumed] = ys[resumed]
            carry[resumed] = 0.0
        errors: np.ndarray = np.abs(ys - (np.minimum(np.maximum(inside, low), high) + carry))
        on_low: np.ndarray = inside <= low
        on_high: np.ndarray = inside >= high
    return errors, on_low, on_high


def _step(value: float, low: float, high: float, low_next: float, high_next: float) -> float:
    """The clamp of eq. (20) one reading on from ``value`` (band ``low .. high``) into the
    band ``low_next .. high_next``: the part inside the band moves, the offset outside it
    stays (a band that lags the drivetrain by an offset lags it as much one reading later)."""
    inside = min(max(value, low), high)
    return min(max(inside, low_next), high_next) + (value - inside)


def _isolated(
    y: float,
    predicted: float,
    low: float,
    high: float,
    y_next: float,
    low_next: float,
    high_next: float,
    limit: float,
) -> bool:
    """Whether the reading ``y`` (band ``low .. high``), far from its prediction
    ``predicted``, is isolated: the reading after it (``y_next``, band ``low_next ..
    high_next``) does not follow it within ``limit``, and lies nearer where the prediction
    leads than where ``y`` leads (a spike jumps and returns; a load that moved where the
    model did not say stays there)."""
    from_y = abs(y_next - _step(y, low, high, low_next, high_next))
    from_predicted = abs(y_next - _step(predicted, low, high, low_next, high_next))
    return from_y > limit and from_predicted < from_y


def _travelling(readings: tuple[float, float, float]) -> bool:
    """Whether three readings in a row travel one way (strictly): a load that moves, at a
    pace of its own. After samples taken out while the servo settled, the first reading
    (judged by the band alone) is where the load was when the readings resumed: inside the
    play, where the model holds a load (eq. 20, ``x(t) = x(t-1)`` between the branches), one
    falls across the gap under gravity or coasts; on a flank, a load behind a servo that lags
    the command catches up with the band (the physics drivetrains: +9, +3, +1.5 mrad a
    reading). Either way the pace changes between the readings, and the readings after the
    first do not lead back to it on a straight line: that is the load's, not a spike's.

    The price: a spike displaced against the motion at such a reading also travels one way
    with the readings after it, and is fed; one displaced along the motion by more than a
    reading's step turns back, and is still caught (as is any spike on a resting load)."""
    a, b, c = readings
    return a < b < c or a > b > c


def _trailing(y: float, predicted: float, y_next: float, y_after: float) -> bool:
    """Whether a reading judged by the band alone (the first after samples taken out while
    the servo settled), off its band by ``y - predicted``, is a load trailing the band: it
    and the two readings after it travel one way (:func:`_travelling`), towards the side the
    band is on. A servo that lags the command leaves the load behind a moving flank when the
    readings resume and it closes on it reading by reading (the physics gravity records:
    3.8 mrad behind, then 0.7, then on it). A spike returns at once instead, and a spike
    ahead of the flank turns back: both are still caught. The price: a spike behind a
    moving flank at such a reading is fed."""
    travelling = _travelling((y, y_next, y_after))
    return travelling and (y - predicted) * (y_next - y) < 0.0


class SpikeScreen:
    """The spike screen of the encoder readings fed to the identifier (module notes).

    It follows the residual scale of the model's one-step predictions, the encoder's count
    and where the readings put the band's edges, and remembers the last sample fed; the
    stream health's stuck check asks it for the scale and whether the estimate may judge
    (:attr:`scale`, :meth:`trusted`).

    Attributes
    ----------
    model_fits : bool
        The compensation guard's judgement: the model describes the drivetrain (a reading
        far from a prediction of a model that does not is no evidence of a spike).
    scale : float or None
        The residual scale of the one-step predictions (None until known). Read only: an
        attribute, not a property, for the stuck check's per-reading look.
    """

    __slots__ = (
        "_converged",
        "_events",
        "_fed_band",
        "_fed_t",
        "_fed_y",
        "_quantum",
        "_resync_since",
        "_shift",
        "_shift_model",
        "model_fits",
        "scale",
    )

    def __init__(self) -> None:
        self._events: list[HealthEvent] = []  # what the current call found (returned)
        self.model_fits = True
        self._fed_t: int | None = None  # the last sample fed (spike prediction)
        self._fed_y: float | None = None
        self._fed_band: tuple[float, float] | None = None  # its band's edges (unshifted)
        self.scale: float | None = None  # robust scale of the one-step prediction errors
        # where the readings put the band's lower and upper edge, against the estimate's
        # band (the edges of the model self._shift_model; see screen)
        self._shift = (0.0, 0.0)
        self._shift_model: GeneralBacklash | None = None
        self._quantum = math.inf  # the smallest change between consecutive readings fed
        self._resync_since: int | None = None  # time of the first sample after a gap
        self._converged = False  # the estimate has converged since the identifier started

    def forget_fed_time(self) -> None:
        """The time line restarted (a clock jump back): the next sample fed is not
        predicted from the last one."""
        self._fed_t = None

    def _found(self) -> list[HealthEvent]:
        """The events of the current call (and a fresh list for the next one)."""
        events, self._events = self._events, []
        return events

    def _drop(self, key: str, reason: str, count: int) -> None:
        self._events.append(Drop(key, reason, count))

    def screen(
        self,
        times: np.ndarray,
        us: np.ndarray,
        ys: np.ndarray,
        est: Estimate,
        resumed: np.ndarray | None = None,
        *,
        silence_ns: int,
    ) -> Screening:
        """Which of the samples (``times``, inputs ``us``, readings ``ys``) to feed: not the
        spikes nor those held back after a gap (see the module notes), judged with ``est``,
        the estimate in use; tracks the scale of the one-step prediction errors.

        The samples are judged in steps of ``SCREEN_SAMPLES``, the scale following each
        step: a feed is judged the same whatever its size (a large one after a dwell, or
        feeds of another size, meet the limits a steady stream of small ones would). The
        usual steps (each reading predicted from the one before it, none too far) are
        judged at once, in numpy steps over the whole feed.

        ``resumed`` marks samples after ones taken out while the servo settled
        (:mod:`genbacklash_core.settling`): they are judged against the model's band alone.
        ``silence_ns`` is the encoder's silence limit: a longer gap before a sample is a
        gap (the sample is not predicted from the one before it).

        Returns the mask of the samples to keep (None to keep them all) and the drops. The
        screen stage breaks the chain of consecutive samples at the next kept sample after
        each one taken out (:func:`~genbacklash_ros.node.sample_rule.keep_breaks`)."""
        model = est.model
        if not isinstance(model, GeneralBacklash):
            self._fed_t, self._fed_y, self._fed_band = int(times[-1]), float(ys[-1]), None
            return Screening(None, [])
        self._track_quantum(ys)
        left, right = model.branches(us)
        low, high = np.minimum(left, right), np.maximum(left, right)
        self._follow_model(model, float(us[0]))
        t_prev, y_prev = self._fed_t, self._fed_y
        # a gap before a sample (or no sample before it): not predicted from the one before
        fresh = np.empty(times.size, dtype=bool)
        np.greater(times[1:] - times[:-1], silence_ns, out=fresh[1:])
        fresh[0] = t_prev is None or y_prev is None or int(times[0]) - t_prev > silence_ns
        n, step = int(ys.size), SCREEN_SAMPLES
        start = 0
        if self._resync_since is None and y_prev is not None and not fresh.any():
            # the usual case, a step at once: each reading predicted from the one before it
            trusted = self.trusted(est)
            previous, band = y_prev, self._band_before()
            while start < n:
                part = slice(start, start + step)
                lows, highs = self._shifted(low[part], high[part])
                errs, on_low, on_high = _one_step_errors(
                    previous,
                    band,
                    ys[part],
                    lows,
                    highs,
                    None if resumed is None else resumed[part],
                )
                if (errs > self._limit(trusted)).any():
                    break  # a spike: this step and those after it sample by sample
                self._track_scale(errs, ys[part])
                y_part = ys[part]
                self._track_shift(
                    y_part[on_low] - low[part][on_low], y_part[on_high] - high[part][on_high], model
                )
                previous, band = float(y_part[-1]), (float(lows[-1]), float(highs[-1]))
                start += step
            if start >= n:
                self._fed_t, self._fed_y = int(times[-1]), float(ys[-1])
                self._fed_band = (float(low[-1]), float(high[-1]))
                return Screening(None, [])
            if start:
                self._fed_t, self._fed_y = int(times[start - 1]), float(ys[start - 1])
                self._fed_band = (float(low[start - 1]), float(high[start - 1]))
        keeps: list[np.ndarray | None] = [None] if start else []
        events: list[HealthEvent] = []
        for first in range(start, n, step):
            part = slice(first, first + step)
            j = first + step  # the reading after the step, its neighbour
            after = None
            if j < n and not fresh[j]:
                after = (
                    float(ys[j]),
                    float(low[j]),
                    float(high[j]),
                    resumed is None or not bool(resumed[j]),
                )
            found = self._screen_step(
                times[part],
                ys[part],
                low[part],
                high[part],
                fresh[part],
                est,
                model,
                None if resumed is None else resumed[part],
                after,
            )
            keeps.append(found.keep)
            events += found.events
        if all(keep is None for keep in keeps):
            return Screening(None, events)
        sizes = [start] if start else []
        sizes += [min(step, n - first) for first in range(start, n, step)]
        keep = np.concatenate(
            [
                np.ones(size, dtype=bool) if part is None else part
                for size, part in zip(sizes, keeps, strict=True)
            ]
        )
        return Screening(keep, events)

    def _limit(self, trusted: bool) -> float:
        """The spike limit now (infinite while the estimate may not judge, or while the
        compensation guard judges that the model does not describe the drivetrain:
        :attr:`model_fits`).

        A reading exactly ``SPIKE_COUNTS`` counts from a prediction that is itself a
        reading is within the limit: the counts floor carries a millionth of a count more,
        so that the rounding of two quantised readings' difference does not decide (the
        physics gravity record, seed 15: a load moving 2 counts inside the play, dropped at
        ``3.0679616e-3 > 3.0679615e-3``)."""
        scale = self.scale
        if trusted and self.model_fits and scale is not None:
            return max(SPIKE_SIGMAS * scale, (SPIKE_COUNTS + 1e-6) * self._quantum)
        return math.inf

    def _screen_step(
        self,
        times: np.ndarray,
        ys: np.ndarray,
        low: np.ndarray,
        high: np.ndarray,
        fresh: np.ndarray,
        est: Estimate,
        model: GeneralBacklash,
        resumed: np.ndarray | None = None,
        after: tuple[float, float, float, bool] | None = None,
    ) -> Screening:
        """:meth:`screen` of one step: the samples (``times``, readings ``ys``, the band
        ``low .. high`` of their commands under ``model``, the estimate's, ``fresh``: after
        a gap, ``resumed``: after the servo settled), sample by sample; ``after``: the
        reading after the step, its band and whether it follows on (not ``resumed``; None:
        none yet, or after a gap).

        A reading far from its prediction is a spike only when it is isolated: the reading
        after it does not follow it (:func:`_follows`). When it does, the readings moved
        where the model did not say (a band that lags the drivetrain's wear, a slip): both
        are fed, and a reading just before them judged by the band alone (``resumed``) that
        neither follows is the isolated one. A reading right before samples taken out while
        the servo settled has only the value of the reading after them to go by: a reading
        that lies between the readings before and after it did not jump."""
        y_prev, band_prev = self._fed_y, self._band_before()
        trusted = self.trusted(est)
        limit = self._limit(trusted)
        resync = self._resync_since
        edges = (low, high)
        low, high = self._shifted(low, high)
        self._fed_t, self._fed_y = int(times[-1]), float(ys[-1])
        self._fed_band = (float(edges[0][-1]), float(edges[1][-1]))
        if resync is None and y_prev is not None and not fresh.any():
            errs, on_low, on_high = _one_step_errors(y_prev, band_prev, ys, low, high, resumed)
            if not (errs > limit).any():
                self._track_scale(errs, ys)
                self._track_shift(
                    ys[on_low] - edges[0][on_low], ys[on_high] - edges[1][on_high], model
                )
                return Screening(None, [])
        pushed: tuple[list[float], list[float]] = ([], [])  # offsets from the edges
        errors: list[float] = []
        bad: list[int] = []  # spikes
        held: list[int] = []  # after a gap, until a sample follows from the one before it
        worst = (0.0, 0.0, 0.0)
        x, (x_low, x_high), x_at = y_prev, band_prev, -1  # the last reading fed (or its stand-in)
        move: float | None = None  # how far the readings moved at the last one fed
        again = [False] * ys.size if resumed is None else resumed.tolist()
        # each reading's neighbour: the next one of the step, or ``after`` (None: none)
        later: list[tuple[float, float, float, bool] | None] = [
            None if new else (y, lo, hi, not res)
            for y, lo, hi, new, res in zip(
                ys[1:].tolist(),
                low[1:].tolist(),
                high[1:].tolist(),
                fresh[1:].tolist(),
                again[1:],
                strict=True,
            )
        ]
        if after is not None:
            shifted = self._shifted(np.array([after[1]]), np.array([after[2]]))
            after = (after[0], float(shifted[0][0]), float(shifted[1][0]), after[3])
        later.append(after)
        by_band: int | None = None  # the last reading judged by the band alone and fed
        for i, (t, y, lo, hi, new, res) in enumerate(
            zip(
                times.tolist(),
                ys.tolist(),
                low.tolist(),
                high.tolist(),
                fresh.tolist(),
                again,
                strict=True,
            )
        ):
            if x is None or (new and not trusted):
                x, x_low, x_high, x_at, move = y, lo, hi, i, None
                continue
            if res:  # the band alone judges it (see _one_step_errors)
                inside, carry = y, 0.0
            else:
                inside = min(max(x, x_low), x_high)
                carry = x - inside
            if new:
                resync = t
            predicted = min(max(inside, lo), hi) + carry  # the clamp of eq. (20)
            error = y - predicted
            if resync is not None:
                if abs(error) <= limit or t - resync >= RESYNC_NS:
                    resync = None  # consistent with the sample before the gap
                    x, x_low, x_high, x_at, move = y, lo, hi, i, None
                else:
                    held.append(i)
                continue
            # a reading judged by the band alone (no reading before it) gets one count more:
            # where the load rests against a flank when the readings resume depends on how
            # far the servo trails the command then, which the learned shift only averages
            # (the physics gravity record, seed 6: 2 counts behind, on the flank at the next)
            far = limit + self._quantum if res else limit
            if abs(error) > far:
                # a load still moving as it moved one reading before (coasting, ringing)
                # is no spike; nor is a reading the one after it sides with
                if move is None or res or abs(y - x - move) > limit:
                    neighbour = later[i]
                    if neighbour is None:
                        isolated = True
                    elif not neighbour[3]:  # after a settling gap: between its neighbours?
                        isolated = not min(x, neighbour[0]) <= y <= max(x, neighbour[0])
                    else:
                        isolated = _isolated(y, predicted, lo, hi, *neighbour[:3], limit)
                        beyond = later[i + 1] if i + 1 < len(later) else None
                        if isolated and res and beyond is not None and beyond[3]:
                            isolated = not _trailing(y, predicted, neighbour[0], beyond[0])
                    if isolated:
                        bad.append(i)
                        x, x_low, x_high, x_at = predicted, lo, hi, i  # stands in for it
                        move = None
                        if abs(error) > abs(worst[1]):
                            worst = (y, error, predicted)
                        continue
                    # a reading just before it judged by the band alone (the commands
                    # before it unknown) that neither follows, nor their motion leads back
                    # to, is the isolated one
                    # (judged by the band alone: one count more, as above; and not when
                    # the three travel one way, at a pace the model does not predict: the
                    # physics drivetrains, see _travelling)
                    if (
                        neighbour is not None
                        and neighbour[3]
                        and by_band == i - 1
                        and abs(x - (2.0 * y - neighbour[0])) > limit + self._quantum
                        and not _travelling((x, y, neighbour[0]))
                    ):
                        bad.append(by_band)
                        back = 2.0 * y - neighbour[0]  # where the readings after it lead
                        if abs(x - back) > abs(worst[1]):
                            worst = (x, x - back, back)
            else:
                errors.append(abs(error))
            by_band = i if res and abs(error) <= far else None
            if inside <= lo:
                pushed[0].append(y - float(edges[0][i]))
            elif inside >= hi:
                pushed[1].append(y - float(edges[1][i]))
            move = y - x if x_at == i - 1 and not res else None
            x, x_low, x_high, x_at = y, lo, hi, i
        self._resync_since = resync
        self._track_scale(np.array(errors), ys)
        self._track_shift(np.array(pushed[0]), np.array(pushed[1]), model)
        if len(bad) > SPIKE_MAX_SHARE * ys.size:
            bad = []  # the model is off rather than the encoder: feed them
        elif bad:
            y, error, predicted = worst
            self._drop(
                "encoder_spike",
                f"encoder reading {y:.6g} is {error:+.3g} from the model's prediction "
                f"{predicted:.6g} (limit {limit:.3g})",
                len(bad),
            )
        if held:
            self._drop("encoder_after_gap", "sample after a gap not yet consistent", len(held))
        if not bad and not held:
            return Screening(None, self._found())
        if x is not None:
            self._fed_y = x
            if x_at >= 0:
                self._fed_band = (float(edges[0][x_at]), float(edges[1][x_at]))
        keep = np.ones(ys.size, dtype=bool)
        keep[bad] = False
        keep[held] = False
        return Screening(keep, self._found())

    def trusted(self, est: Estimate) -> bool:
        """Whether ``est`` may judge the readings (spikes, stuck, gaps): the identifier has
        converged since it last (re)started, and a residual scale is known."""
        state = est.state
        if state is EstimatorState.CONVERGED:
            self._converged = True
        elif state in (EstimatorState.WARMING_UP, EstimatorState.DIVERGED):
            self._converged = False
            self._shift = (0.0, 0.0)
        return self._converged and self.scale is not None

    def _band_before(self) -> tuple[float, float]:
        """The band (shifted) of the last reading fed; unbounded when not known."""
        band = self._fed_band
        if band is None:
            return (-math.inf, math.inf)
        low, high = self._shifted(np.array([band[0]]), np.array([band[1]]))
        return (float(low[0]), float(high[0]))

    def _shifted(self, low: np.ndarray, high: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The band ``low .. high`` with its edges where the readings put them."""
        shift_low, shift_high = self._shift
        if shift_low == 0.0 and shift_high == 0.0:
            return low, high
        return low + shift_low, np.maximum(high + shift_high, low + shift_low)

    def _follow_model(self, model: GeneralBacklash, u: float) -> None:
        """Keep the edges where the readings put them when the estimate moves its band:
        the shifts change by what the new model moves each edge at the command ``u``."""
        old = self._shift_model
        if old is model:
            return
        self._shift_model = model
        if old is None or self._shift == (0.0, 0.0):
            return
        left0, right0 = old.branches_at(u)
        left1, right1 = model.branches_at(u)
        moved = (
            self._shift[0] + min(left0, right0) - min(left1, right1),
            self._shift[1] + max(left0, right0) - max(left1, right1),
        )
        self._shift = self._bounded(moved, model)

    def _track_shift(
        self, off_low: np.ndarray, off_high: np.ndarray, model: GeneralBacklash
    ) -> None:
        """Blend a step's offsets of the readings pushed by the band's lower and upper edge
        (``y - edge``, the estimate's edges) into the edges' shifts: their median, from
        ``_SHIFT_MIN_READINGS`` readings on, while the estimate may judge."""
        if not self._converged:
            return
        shift = list(self._shift)
        for side, offsets in enumerate((off_low, off_high)):
            if offsets.size < _SHIFT_MIN_READINGS:  # too few, finite or not
                continue
            offsets = offsets[np.isfinite(offsets)]
            if offsets.size >= _SHIFT_MIN_READINGS:
                shift[side] += _SHIFT_SMOOTHING * (exact_median(offsets) - shift[side])
        self._shift = self._bounded((shift[0], shift[1]), model)

    @staticmethod
    def _bounded(shift: tuple[float, float], model: GeneralBacklash) -> tuple[float, float]:
        """``shift`` within ``SHIFT_PLAY_SHARE`` of the play of ``model`` (0 where not finite)."""
        bound = SHIFT_PLAY_SHARE * abs(model.c_left + model.c_right)
        if not math.isfinite(bound):
            return (0.0, 0.0)
        low, high = shift
        low = min(max(low, -bound), bound) if math.isfinite(low) else 0.0
        high = min(max(high, -bound), bound) if math.isfinite(high) else 0.0
        return (low, high)

    def _track_quantum(self, ys: np.ndarray) -> None:
        """Lower the encoder count to the smallest change between consecutive readings of
        ``ys`` (an encoder without quantisation soon makes it negligible)."""
        if ys.size > 1:
            with np.errstate(all="ignore"):
                steps = np.abs(ys[1:] - ys[:-1])
                # NaN and equal readings out (none left: inf, the count unchanged)
                moved = steps[steps > 0.0]
                smallest = float(moved.min()) if moved.size else math.inf
            self._quantum = min(self._quantum, smallest)

    def _track_scale(self, errors: np.ndarray, ys: np.ndarray) -> None:
        """Blend a step's absolute prediction errors into the residual scale (their upper
        quartile / 1.15, a normal sigma; at least 1e-3 of the readings' magnitude)."""
        errors = errors[np.isfinite(errors)]  # an overflowing branch gives NaN or inf
        if errors.size == 0:
            return
        k = (errors.size - 1) * 3 // 4
        floor = 1e-3 * float(np.maximum.reduce(np.abs(ys)))  # np.max without its wrapper
        errors.partition(k)  # in place: ``errors`` is this step's own copy
        batch = max(float(errors[k]) / 1.15, floor, 1e-300)
        if batch < math.inf:
            scale = self.scale
            self.scale = batch if scale is None else scale + _SCALE_SMOOTHING * (batch - scale)
