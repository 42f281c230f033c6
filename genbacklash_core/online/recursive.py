"""Recursive identification whose memory is measured in information, not in samples.

The parameter vector is the separated one of eqs. (23)/(33); the regression rows are those of
eq. (22) (backlash) or eq. (32) (cascade), with the switching functions (eqs. 27-28) and
``xi`` (eqs. 25-26) evaluated at the current estimate and, for the cascade, the internal
output ``x`` of eq. (36) propagated sample by sample with it.

A drivetrain delivers its information in moves and reversals separated by long dwells; at
1 kHz a command held for ten readings repeats one state ten times. So the memory here holds
*rows*, not samples:

* **Rows of moves.** A row pairs samples that are consecutive on the encoder's clock and
  between which the input moved; a hold reads the anchor its engaged row left
  (:mod:`~genbacklash_core.online.stream`). A dwell or a held command adds no row, so it
  never pushes anything out of the memory.
* **Binned memory.** Rows are filed by branch and input region; each branch keeps its newest
  ``M = 1 / (1 - forgetting)`` rows and every region a floor of rows however old
  (:class:`~genbacklash_core.online.memory.BinnedRows`): old information is forgotten only as
  newer rows of the same branch arrive, never entirely where no new data cover the region.
* **One iteration per block.** Every ``block`` samples with new rows, one warm-started
  iteration of the paper's method runs over the whole memory: the rows are re-evaluated at
  the current estimate (eqs. 25-28) and the least squares of eq. (29) / (37) is solved, with
  a weak pull ``R_0 = R_init / covariance_bound`` towards the current estimate (no wind-up,
  never singular)::

      (Phi^T Phi + R_0) theta_new = Phi^T z + R_0 theta

  Its cost grows with the memory (~40 us for 1000 rows), not with the samples; a block
  without new rows costs nothing and changes nothing.
* **Cold start from everything seen.** Until the first estimate, every informative row since
  the start is kept (binned the same way); a batch start
  (:mod:`~genbacklash_core.online.restart`) runs on them whenever the memory has grown by a
  quarter. The cascade's internal ``x`` needs an estimate, so it starts from a batch fit
  over its recent ``buffer`` samples instead.
* **No excitation is not divergence.** Without new rows nothing changes: the estimate holds,
  the state is ``no_excitation`` after ``idle_samples`` samples without information, and the
  confidence fades with the age of the information
  (:func:`~genbacklash_core.estimate.aged_confidence`; the age of the branch whose newest row
  is oldest, half-life ``confidence_half_life``).
* **Divergence only on failure.** An iterate that leaves the valid set (flipped slope,
  negative dead zone, crossing branches, unstable linear block, non-finite) is not taken;
  persistent failure re-initialises from the memory. A one-step error that blows up against
  its running scale (a sensor fault, a sudden change) holds the estimate and keeps the new
  rows out of the memory (state ``diverged``) until the errors are normal again, or until a
  batch fit on the rows held back fits and replaces the memory.

:meth:`RecursiveIdentifier.update` and :meth:`RecursiveIdentifier.update_many` queue the
samples and process them at the same fixed sample counts (every ``block`` samples; the batch
fits' attempts), so they agree to rounding whatever the chunking; between two such events
only the sample count (and the aged confidence) of the estimate changes.

This module holds the identifier itself (the queue, the blocks, when to iterate, hold or
re-initialise, what it publishes); the other parts stand in the sibling modules of
:mod:`genbacklash_core.online` (see there), one concept each.
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.estimate import (
    Estimate,
    EstimatorState,
    aged_confidence,
    confidence_of,
)

from .advice import BranchCoverage, coverage_of, excitation_advice
from .base import OnlineIdentifier
from .covariance import natural_covariance, natural_from_theta, scaled_inverse
from .divergence import ErrorScale
from .inputs import (
    settings_or_default,
    template,
)
from .iteration import Iterate, ewma, theta_problem
from .memory import BinnedRows
from .restart import backlash_start, cascade_start, rejected
from .rows import (
    row_width,
    settling_samples,
)
from .seed import SeedPrior, prior_weights
from .settings import RecursiveSettings
from .state import confidence_moved, held, settled_state
from .stream import RowStream
from .tracking import BAND_SAMPLES, dead_zone_drift, with_tracking

__all__ = ["RecursiveIdentifier", "RecursiveSettings"]

_MAX_INVALID = 8  # consecutive invalid iterates before a re-initialisation
_DRIFT_EVERY = 250  # samples between two fits of the bands' tracking term (~0.3 ms each)

_WARMING, _RUNNING, _HELD, _STOPPED = "warming", "running", "held", "stopped"


class RecursiveIdentifier(OnlineIdentifier[RecursiveSettings]):
    """Online identification over a binned memory of regression rows (see the module notes).

    Parameters
    ----------
    degree : int
        Polynomial degree of each branch.
    na, nb : int
        Linear block orders (eq. 30); ``na = 0`` (default) identifies a backlash alone.
    sign : {+1, -1, None}
        Branch sense; None detects it at the first batch fit.
    settings : RecursiveSettings, optional

    Examples
    --------
    >>> from genbacklash_core import paper_example
    >>> ex = paper_example(1)
    >>> data = ex.generate(seed=0, n_samples=3000)
    >>> ident = RecursiveIdentifier(degree=3)
    >>> est = ident.update_many(data.u, data.y)
    >>> est.state.value, est.samples
    ('converged', 3000)
    >>> bool(np.max(np.abs(est.parameters - ex.model.parameters())) < 0.03)
    True
    >>> ident.update(0.5, 0.1).samples
    3001

    A drivetrain in operation (moves, dwells, 100 Hz commands read at 1 kHz, 2 % of the
    readings lost): the sample rule's ``breaks`` keep rows from pairing readings that are
    not neighbours, and the dwells add nothing to the memory:

    >>> from genbacklash_core.scenarios import operation_record, OperationSettings
    >>> rec = operation_record(OperationSettings(duration=10.0), seed=0)
    >>> u, y, breaks = rec.series()
    >>> est = RecursiveIdentifier(degree=3).update_many(u, y, breaks)
    >>> est.available, bool(np.max(np.abs(est.parameters - rec.truth.parameters())) < 0.01)
    (True, True)

    After a restart, continue from a saved estimate instead of a new batch fit:

    >>> again = RecursiveIdentifier(degree=3)
    >>> seeded = again.seed(est)
    >>> seeded.state.value, bool(np.allclose(seeded.parameters, est.parameters))
    ('converged', True)
    """

    def __init__(
        self,
        degree: int = 3,
        na: int = 0,
        nb: int = 0,
        *,
        sign: float | None = None,
        settings: RecursiveSettings | None = None,
    ) -> None:
        shape = template(degree, na, nb, sign)
        settings = settings_or_default(settings, RecursiveSettings)
        # the longest regression: the cascade's buffer or both branches' memories
        super().__init__(shape, settings, max(settings.buffer, 2 * settings.branch_memory))

    _CHECK_FOLLOWS = True  # (it always did)

    @property
    def restarts(self) -> int:
        """How many times the identification was re-initialised after a divergence."""
        return self._restarts

    @property
    def memory(self) -> BinnedRows:
        """The rows the estimate rests on (read only; see :class:`BinnedRows`)."""
        return self._memory

    @property
    def coverage(self) -> BranchCoverage:
        """How much of the input range each branch's rows cover (the memory and the rows of
        the current block), for diagnostics and reports."""
        rows, _ = self._memory.rows()
        if self._pending:
            rows = np.concatenate([rows, *(r for r, _ in self._pending)])
        return coverage_of(rows[:, 0], rows[:, 1], self.settings.bins, self._memory.per_direction)

    def excitation_advice(self) -> str:
        """What the data have not shown yet, and what motion would show it ("" when the rows
        cover both branches over the input range seen). A backlash alone only (the cascade's
        rows are not filed by branch): "" for a cascade.

        >>> ident = RecursiveIdentifier(1)
        >>> _ = ident.update_many(np.linspace(0.0, 1.0, 400), np.linspace(0.0, 0.9, 400))
        >>> ident.excitation_advice()
        'the left branch is not covered yet: move the joint down'
        """
        if self._status.structure.cascade:
            return ""
        need = 0 if self._ever_started else max(self._min_rows() - len(self._memory), 0)
        cover = self.coverage
        seen = bool(cover.up.sum() + cover.down.sum()) or self._stream.high > self._stream.low
        queued = any(np.ptp(u) > 0.0 for u, _, _ in self._queue if u.size)
        if not seen and queued:
            return ""  # the samples are not looked at before the first attempt
        return excitation_advice(cover, moved=seen or queued, rows_needed=need)

    @property
    def from_seed(self) -> bool:
        """True while the estimate still leans on a seed (:meth:`seed`): the memory has not
        refilled a branch since (and no re-initialisation replaced the seed)."""
        return self._current.prior is not None and bool(
            np.any(prior_weights(self._status.structure, self._memory) > 0.0)
        )

    def reset(self) -> None:
        """Forget all samples and the estimate."""
        self._forget()
        s = self.settings
        structure = self._template
        self._mode = _WARMING
        self._ever_started = False
        self._restarts = 0
        self._why = ""  # why the identification diverged (held or stopped)
        self._current = Iterate(structure.n_parameters)  # theta, its information, its version
        # the memory, the rows held back while the errors are blown up, the recent samples
        self._memory = self._new_memory(row_width(structure))
        self._held_back: BinnedRows | None = None
        self._stream = RowStream(structure, s.buffer)  # the recent samples; carried signals
        self._pending: list[tuple[FloatArray, IntArray]] = []  # rows of the current block
        self._queue: list[tuple[FloatArray, FloatArray, BoolArray]] = []  # samples not seen
        self._queued = 0
        self._events = 0  # queue flushes (the estimate's excitation and ages change there)
        self._published: tuple[tuple[object, ...], Estimate] | None = None
        self._next_drift = 0  # the sample from which the next iterate refits it
        self._drift_at = 0  # the sample it was fitted at
        self._committed_at = 0  # the sample of the last iterate taken
        self._settling = 0
        self._settled_at = 0  # sample count of the last settling-horizon update
        # schedule
        self._next_solve = 0
        self._next_attempt = s.initial_samples
        self._attempts = 0
        self._fresh = 0  # rows filed since the last batch-fit attempt (backlash)
        self._need = self._min_rows()  # fresh rows the next attempt waits for
        # measures
        self._errors = ErrorScale()  # the one-step errors' running means (divergence test)
        self._scale_before = math.nan
        blocks = 3 if structure.cascade else 2
        self._last_row = [0] * blocks  # sample count at the newest row of left, right, linear

    def _continue_from(self, prior: SeedPrior, estimate: Estimate) -> None:
        """Continue from a seed (:meth:`seed`): its parameters (eq. 34 inverted) as the
        current estimate; its information joins each iteration as a prior weighted by the
        share of the memory the new rows have not refilled yet (per branch). A cascade
        waits for the samples that determine its internal ``x`` (the play operator started
        from any state agrees) before it takes rows."""
        cov = scaled_inverse(prior.information)
        assert cov is not None  # (_check_seed)
        s = self.settings
        self._current.seed(prior, cov, s.covariance_bound)
        self._errors.restart(prior.sigma2)
        self._last_row = [self._status.samples] * len(self._last_row)
        if self._status.structure.cascade:
            self._settling = settling_samples(self._status.structure, prior.p)
        self._mode = _RUNNING
        self._ever_started = True
        self._next_solve = self._status.samples + s.block
        self._status.reason = f"seeded from a saved estimate ({estimate.state.value})"

    def _check_seed(self, prior: SeedPrior) -> None:
        if scaled_inverse(prior.information) is None:  # seed_prior checked that it is
            raise GenBacklashError("cannot seed: the estimate's information is singular")

    def refit(self) -> Estimate:
        """Iterate over the memory now, with the rows since the last block boundary, instead
        of at the next one (for a final estimate at the end of a record). The schedule is
        unchanged; :meth:`update` and :meth:`update_many` no longer agree exactly after it."""
        self._flush()
        if self._mode in (_RUNNING, _HELD):
            due = self._next_solve
            self._event()
            self._next_solve = due
        elif self._mode in (_WARMING, _STOPPED):
            self._file(self._memory, *self._pending_rows())
            if len(self._memory) >= self._min_rows() and not self._status.structure.cascade:
                self._initialise()
        self._estimate = None
        return self.estimate

    # ------------------------------------------------------------------ feeding samples

    def _new_memory(self, width: int) -> BinnedRows:
        """An empty memory as the settings ask."""
        s = self.settings
        return BinnedRows(width, s.bins, s.branch_memory, s.region_floor)

    def _min_rows(self) -> int:
        """Rows a batch fit on the memory needs at least."""
        return max(3 * self._template.n_parameters, 20)

    def _take(self, u: FloatArray, y: FloatArray, b: BoolArray) -> None:
        """Queue validated samples; process the queue at each of the schedule's events."""
        self._estimate = None
        if u.size == 0:
            return
        if self._mode in (_RUNNING, _HELD):
            why = theta_problem(self._status.structure, self._current.theta)
            if why is not None:  # e.g. a corrupted state: never iterate from it
                self._stop(why)
        start = 0
        while start < u.size:
            due = self._next_solve if self._mode in (_RUNNING, _HELD) else self._next_attempt
            take = min(u.size - start, max(due - self._status.samples, 1))
            part = slice(start, start + take)
            self._queue.append((u[part], y[part], b[part]))
            self._queued += take
            self._status.samples += take
            start += take
            if self._status.samples >= due:
                self._flush()
                self._event()

    def _flush(self) -> None:
        """Process the queued samples (rows, errors, excitation) in one piece."""
        if not self._queued:
            return
        if len(self._queue) == 1:
            u, y, b = self._queue[0]
        else:
            u = np.concatenate([q[0] for q in self._queue])
            y = np.concatenate([q[1] for q in self._queue])
            b = np.concatenate([q[2] for q in self._queue])
        first = self._status.samples - self._queued
        self._queue = []
        self._queued = 0
        self._events += 1
        self._piece(u, y, b, first)

    def _piece(self, u: FloatArray, y: FloatArray, b: BoolArray, first: int) -> None:
        """Rows, errors and excitation of a stretch of samples within one block."""
        s = self.settings
        running = self._mode in (_RUNNING, _HELD)  # else: warming up or stopped
        rows, at = self._stream.take(
            self._status.structure,
            self._current.theta if running else None,
            u,
            y,
            b,
            s.input_deadband,
            self._settling,
        )
        informative = np.zeros(u.size)
        if at.size:
            stamps = np.asarray(first + at, dtype=np.intp)
            if running:
                informative = self._judge(rows, stamps, at, u.size)
            else:  # filed at the next batch-fit attempt
                self._pending.append((rows, stamps))
                informative[at] = 1.0
        self._status.excitation = ewma(
            informative, 1.0 / s.excitation_memory, self._status.excitation
        )

    def _judge(self, rows: FloatArray, stamps: IntArray, at: IntArray, n: int) -> FloatArray:
        """A priori one-step errors of new rows at the current estimate (eqs. 24/35), kept
        for the block's end; which samples informed which block."""
        structure = self._status.structure
        used, left, right = self._errors.judge(
            structure,
            self._current.theta,
            self._current.unit_cov,
            rows,
            ratio=self.settings.divergence_ratio,
            running=self._mode == _RUNNING,  # while held, the scale holds
        )
        self._pending.append((rows, stamps))
        informative = np.zeros(n)
        informative[at[used]] = 1.0
        newest = stamps[used] + 1
        if newest.size:
            if left.any():
                self._last_row[0] = int(newest[left][-1])
            if right.any():
                self._last_row[1] = int(newest[right][-1])
            if structure.cascade:
                self._last_row[2] = int(newest[-1])
        return informative

    def _file(self, memory: BinnedRows, rows: FloatArray, stamps: IntArray) -> None:
        """File rows into a memory, counting them for the batch-fit schedule."""
        if rows.shape[0]:
            memory.insert(rows, stamps)
            self._fresh += rows.shape[0]

    # ------------------------------------------------------------------ the schedule

    def _event(self) -> None:
        """The end of a block (running, held) or a batch-fit attempt (warming, stopped)."""
        if self._mode == _RUNNING:
            self._end_block()
        elif self._mode == _HELD:
            self._end_held_block()
        else:
            self._attempt()

    def _pending_rows(self) -> tuple[FloatArray, IntArray]:
        """The rows of the block, taken out of the queue."""
        if not self._pending:
            return np.empty((0, self._memory.width)), np.empty(0, dtype=np.intp)
        rows = np.concatenate([r for r, _ in self._pending])
        stamps = np.concatenate([t for _, t in self._pending])
        self._pending = []
        return rows, stamps

    def _blown(self) -> bool:
        """The short-term one-step error exceeds ``divergence_ratio`` times its scale."""
        return self._errors.blown(self.settings.divergence_ratio)

    def _end_block(self) -> None:
        """File the block's rows and iterate over the memory (when it got new rows)."""
        s = self.settings
        self._next_solve = self._status.samples + s.block
        rows, stamps = self._pending_rows()
        if self._blown():
            self._mode = _HELD
            self._scale_before = self._errors.long
            self._attempts = 0
            self._next_attempt = self._status.samples + self._attempt_interval()
            if not self._status.structure.cascade:
                self._held_back = self._new_memory(self._memory.width)
            self._fresh = 0
            self._need = self._min_rows()
            if self._held_back is not None:
                self._file(self._held_back, rows, stamps)
            self._why = (
                f"the one-step error blew up (RMS {math.sqrt(self._errors.short):.3g} against "
                f"a running {math.sqrt(self._errors.long):.3g}); the estimate is held and new "
                "rows are kept out of the memory"
            )
            self._status.reason = ""
            return
        self._file(self._memory, rows, stamps)
        if rows.shape[0]:
            self._iterate()
        if (
            self._status.structure.cascade
            and self._status.samples - self._settled_at >= s.check_every
        ):
            self._settled_at = self._status.samples
            self._settling = settling_samples(
                self._status.structure, self._status.structure.from_theta(self._current.theta)
            )

    def _end_held_block(self) -> None:
        """Resume when the errors are normal again; else hold the rows back and try a batch
        fit on them (backlash) or on the recent samples (cascade) when due."""
        self._next_solve = self._status.samples + self.settings.block
        rows, stamps = self._pending_rows()
        if not self._blown():
            self._mode = _RUNNING
            self._held_back = None
            self._status.reason = ""
            self._file(self._memory, rows, stamps)
            if rows.shape[0]:
                self._iterate()
            return
        if self._held_back is not None:
            self._file(self._held_back, rows, stamps)
        if self._attempt_due():
            self._initialise()

    def _attempt(self) -> None:
        """File the rows since the last attempt point; a batch-fit attempt when due."""
        self._file(self._memory, *self._pending_rows())
        if self._attempt_due():
            self._initialise()
        elif not self._status.structure.cascade:
            self._next_attempt = self._status.samples + self.settings.block

    def _attempt_due(self) -> bool:
        """A backlash fits its rows once they grew by a quarter since the last attempt; the
        cascade fits its recent samples at growing intervals."""
        if self._status.structure.cascade:
            return self._status.samples >= self._next_attempt
        source = self._held_back if self._mode == _HELD else self._memory
        if source is None:
            return False
        return len(source) >= self._min_rows() and self._fresh >= self._need

    def _attempt_interval(self) -> int:
        """Samples to the next batch-fit attempt of the cascade (doubling, at most buffer)."""
        s = self.settings
        interval: int = max(s.initial_samples // 4, 1) * 2 ** min(self._attempts, 6)
        return min(interval, s.buffer)

    # ------------------------------------------------------------------ (re)initialisation

    def _initialise(self) -> bool:
        """Start (or restart) from a batch fit (:mod:`~genbacklash_core.online.restart`): a
        backlash on every row of its memory (or, while the errors are blown up, the rows
        held back since); the cascade on its recent samples: the whole buffer at first, the
        latest ``initial_samples`` on retried restarts. Returns whether it started."""
        s = self.settings
        structure = self._status.structure
        attempt = self._attempts
        self._attempts += 1
        self._next_attempt = self._status.samples + (
            self._attempt_interval() if structure.cascade else s.block
        )
        span = (self._stream.low, self._stream.high)
        if structure.cascade:
            latest = self._ever_started and attempt > 0  # a retried restart: the latest only
            last = s.initial_samples if latest else s.buffer
            u, y = (a.copy() for a in self._stream.recent.window(last))
            window = (u, y, self._stream.recent.breaks(last))
            first = self._status.samples - self._queued - u.size  # the window ends at the last seen
            memory = self._new_memory(self._memory.width)
            start = cascade_start(structure, self._status.sign_now, window, first, memory, s, span)
        else:
            source = self._held_back if self._mode == _HELD else self._memory
            assert source is not None  # (_attempt_due checked it)
            self._fresh = 0
            self._need = max(len(source) // 4, 1)
            start = backlash_start(structure, self._status.sign_now, source, s, span)
        if isinstance(start, str):
            self._status.reason = f"batch fit failed: {start}"
            return False
        sigma2 = start.solution.sigma2
        why = rejected(sigma2, self._scale_before, s.divergence_ratio, attempt)
        if why is not None:
            self._status.reason = why
            return False
        if self._ever_started:
            self._restarts += 1
        self._status.drift, self._next_drift = (
            None,
            0,
        )  # a new memory: refit the bands' term at once
        self._status.structure = structure = start.structure
        self._status.sign_now = True
        self._memory = start.memory
        self._held_back = None
        if start.lags is not None:
            self._stream.lags = start.lags
        self._current.start(start.solution, start.pull)
        self._committed()
        self._errors.restart(max(sigma2, 1e-300))
        self._scale_before = math.nan
        self._attempts = 0
        self._mode = _RUNNING
        self._ever_started = True
        self._next_solve = self._status.samples + s.block
        self._last_row = [self._status.samples] * len(self._last_row)
        if structure.cascade:
            theta = start.solution.theta
            self._settling = settling_samples(structure, structure.from_theta(theta))
            self._settled_at = self._status.samples
        self._pending = []
        self._status.reason = ""
        return True

    # ------------------------------------------------------------------ the iteration

    def _iterate(self) -> None:
        """One iteration over the memory; an invalid iterate is not taken (the estimate
        holds), and ``_MAX_INVALID`` of them in a row re-initialise from the memory."""
        span = (self._stream.low, self._stream.high)
        why = self._current.step(self._status.structure, self._memory, span)
        if why is None:
            self._committed()
        elif self._current.invalid >= _MAX_INVALID:
            self._stop(f"{self._current.invalid} iterations in a row left the valid set ({why})")

    def _committed(self) -> None:
        """An iterate was taken: its sample, and the bands' tracking term when due."""
        self._committed_at = self._status.samples
        self._track_drift()

    # ------------------------------------------------------------------ divergence

    def _stop(self, why: str) -> None:
        """The estimate left the valid set: re-initialise at once from the memory (backlash)
        or the recent samples (cascade); the last valid estimate stands meanwhile."""
        self._mode = _STOPPED
        self._held_back = None
        self._file(self._memory, *self._pending_rows())  # the data are sound: keep them
        self._scale_before = self._errors.long
        self._attempts = 0
        self._fresh = self._need = len(self._memory)  # (the memory is due now)
        self._current.restore(self._status.structure)
        self._why = why
        self._initialise()

    def _track_drift(self) -> None:
        """The tracking term of the bands (:mod:`genbacklash_core.online.tracking`): the memory's
        rows, aged from this iterate's sample, fitted with dead zones that drift. Once per
        :data:`_DRIFT_EVERY` samples at most (a fit over the memory costs ~1-2 ms), at the
        iterates' own samples, so chunking does not matter. Nothing for the cascade."""
        structure = self._status.structure
        if structure.cascade or self._status.samples < self._next_drift:
            return
        self._next_drift = self._status.samples + _DRIFT_EVERY
        self._drift_at = self._status.samples
        rows, stamps = self._memory.rows()
        p = np.array(natural_from_theta(structure, self._current.theta.tolist()))
        cols = (rows[:, 0], rows[:, 1], rows[:, 2], rows[:, 3])
        ring = self._stream.recent  # the latest readings, for the model term's free run
        u, y = ring.window(BAND_SAMPLES)
        recent = (u, y, ring.breaks(BAND_SAMPLES))
        self._status.drift = dead_zone_drift(
            structure, p, cols, float(self._status.samples) - stamps, recent
        )

    # ------------------------------------------------------------------ the estimate

    def _publish(self) -> Estimate:
        """The estimate, its state and confidence, from the current internals.

        Between the schedule's events only the sample count and, slowly, the aged
        confidence change: the last estimate is then reused with the new count.
        """
        structure = self._status.structure
        s = self.settings
        excitation = min(max(self._status.excitation, 0.0), 1.0)
        if not self._ever_started:
            reason = self._status.reason
            if not structure.cascade:
                rows = sum(r.shape[0] for r, _ in self._pending)
                advice_key = (self._events, len(self._memory), rows)  # rows come at events
                reason = self._advice.reason(reason, advice_key, self.excitation_advice)
            return Estimate.empty(
                structure, self._status.samples, excitation, EstimatorState.WARMING_UP, reason
            )
        current = self._current
        sigma2 = current.sigma2 if math.isfinite(current.sigma2) else self._errors.long
        p_list, rel = current.summary(structure, sigma2)
        idle = self._status.samples - max(self._last_row)  # since the newest informative row
        age = self._status.samples - min(self._last_row)  # of the branch whose newest row is oldest
        if self._mode in (_HELD, _STOPPED):
            state = EstimatorState.DIVERGED
        elif held(idle, s.idle_samples):
            state = EstimatorState.NO_EXCITATION
        else:  # one iteration per block: the estimate is as settled as its memory
            state = settled_state(True, rel, s.converged_std)
        confidence = aged_confidence(
            confidence_of(state, rel, s.converged_std), float(age), s.confidence_half_life
        )
        key = (
            current.version,
            self._events,
            state,
            self._status.reason,
            current.note,
            self._restarts,
        )
        if self._published is not None and self._published[0] == key:
            last = self._published[1]
            if not confidence_moved(confidence, last.confidence, floor=0.0):
                return last.with_samples(self._status.samples)
        if state is EstimatorState.DIVERGED:
            reason = f"diverged: {self._why}"
            if self._status.reason:
                reason += f"; re-initialisation pending ({self._status.reason})"
        elif state is EstimatorState.NO_EXCITATION:
            reason = (
                f"estimate held: no new information for {s.idle_samples} samples or more "
                f"(the input rests, repeats or moves too little); {len(self._memory)} rows "
                "remembered"
            )
        else:
            reason = f"{len(self._memory)} rows remembered; relative std {rel:.3g}"
            if self.from_seed:
                reason = f"{self._status.reason}; {reason}"
            if self._restarts:
                reason += f"; re-initialised {self._restarts} time(s)"
        if current.note and state is not EstimatorState.DIVERGED:
            reason += f"; {current.note}"
        recent = self._errors.recent
        residual = recent if math.isfinite(recent) else sigma2
        theta_copy = current.theta.copy()
        cov_theta = sigma2 * current.unit_cov  # sigma^2 (Phi^T Phi + R_0 + prior)^-1
        drift = self._status.drift
        p_now = np.array(p_list)
        # the drift goes on between its fits (one per _DRIFT_EVERY samples): counted to the
        # last iterate's sample, not the publishing moment (chunking must not matter)
        ticks = float(self._committed_at - self._drift_at)
        est = Estimate.trusted(
            structure,
            p_now,
            lambda: with_tracking(
                natural_covariance(structure, theta_copy, cov_theta), drift, p_now, ticks
            ),
            math.sqrt(residual),
            excitation,
            state,
            confidence,
            self._status.samples,
            reason,
        )
        self._published = (key, est)
        return est
