"""The recursive identifier's blocks: when it files rows, iterates, holds and re-initialises.

:class:`BlockMachine` is the recursive identifier's estimation between two of its events
(:mod:`~genbacklash_core.online.queue`): at each, the samples queued since become rows
(:class:`~genbacklash_core.online.stream.RowStream`), judged by their one-step errors at the
current estimate (:class:`~genbacklash_core.online.divergence.ErrorScale`), and what happens
to them depends on the mode:

* **warming** (no estimate yet) and **stopped** (the estimate left the valid set): the rows
  are filed into the memory, and a batch fit (:mod:`~genbacklash_core.online.restart`) is
  tried when due (:class:`~genbacklash_core.online.attempts.AttemptSchedule`);
* **running**: at the end of each ``block`` samples, the block's rows are filed and one
  iteration runs over the whole memory (:class:`~genbacklash_core.online.iteration.Iterate`;
  eqs. 25-29, 37); ``MAX_INVALID`` invalid iterates in a row re-initialise from the memory;
* **held** (the one-step error blew up against its running scale: a sensor fault, a sudden
  change): the estimate holds and the new rows are kept out of the memory, until the errors
  are normal again, or until a batch fit on the rows held back (the cascade: on its recent
  samples) fits and replaces the memory.

It keeps the current estimate and the memory it rests on, the ages of the information
(:class:`~genbacklash_core.online.ages.RowAges`), the cascade's settling horizon, and when
the bands' tracking term is refitted (:class:`~genbacklash_core.online.bands.BandSchedule`).

Examples
--------
>>> from genbacklash_core import Structure, paper_example
>>> data = paper_example(1).generate(seed=0, n_samples=600)
>>> status = IdentifierStatus(Structure(3), sign_now=False)
>>> machine = BlockMachine(status, RecursiveSettings(), SampleQueue())
>>> machine.mode, machine.due
('warming', 300)
>>> status.samples = 600
>>> machine.piece(data.u, data.y, np.zeros(600, dtype=bool), first=0)
>>> machine.event()
>>> machine.mode, machine.ever_started
('running', True)
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray

from .ages import RowAges
from .attempts import AttemptSchedule
from .bands import BandSchedule
from .divergence import ErrorScale
from .iteration import Iterate, ewma, theta_problem
from .memory import BinnedRows
from .queue import SampleQueue
from .restart import backlash_start, cascade_start, rejected
from .rows import row_width, settling_samples
from .seed import SeedPrior, prior_weights
from .settings import RecursiveSettings
from .status import IdentifierStatus
from .stream import RowStream

__all__ = ["MAX_INVALID", "BlockMachine"]

MAX_INVALID = 8  # consecutive invalid iterates before a re-initialisation

WARMING, RUNNING, HELD, STOPPED = "warming", "running", "held", "stopped"


class BlockMachine:
    """The recursive identifier's estimation over blocks of samples (see the module notes).

    Parameters
    ----------
    status : IdentifierStatus
        The identifier's status: the machine moves its structure, reason, excitation and
        drift.
    settings : RecursiveSettings
    queue : SampleQueue
        The identifier's queue (a batch start of the cascade ends its window at the last
        sample seen, before the queued ones).
    """

    def __init__(
        self, status: IdentifierStatus, settings: RecursiveSettings, queue: SampleQueue
    ) -> None:
        structure = status.structure
        self._status, self._settings, self._queue = status, settings, queue
        self.mode = WARMING
        self.ever_started = False
        self.restarts = 0
        self.why = ""  # why the identification diverged (held or stopped)
        self.current = Iterate(structure.n_parameters)  # theta, its information, its version
        # the memory, the rows held back while the errors are blown up, the recent samples
        self.memory = self._new_memory(row_width(structure))
        self.held_back: BinnedRows | None = None
        self.stream = RowStream(structure, settings.buffer)  # the recent samples; carried
        self.pending: list[tuple[FloatArray, IntArray]] = []  # rows of the current block
        self.attempts = AttemptSchedule(settings, structure)
        self.errors = ErrorScale()  # the one-step errors' running means (divergence test)
        self.ages = RowAges(structure.cascade)
        self.bands = BandSchedule()
        self._scale_before = math.nan
        self._settling = 0
        self._settled_at = 0  # sample count of the last settling-horizon update
        self._next_solve = 0

    @property
    def events(self) -> int:
        """The queue's events so far (the estimate's excitation and ages change there)."""
        return self._queue.events

    @property
    def running(self) -> bool:
        """Whether there is an estimate to iterate from (running or held)."""
        return self.mode in (RUNNING, HELD)

    @property
    def due(self) -> int:
        """The sample count of the next event: a block's end or a batch-fit attempt."""
        return self._next_solve if self.running else self.attempts.next_attempt

    @property
    def from_seed(self) -> bool:
        """True while the estimate still leans on a seed: the memory has not refilled a
        branch since (and no re-initialisation replaced the seed)."""
        return self.current.prior is not None and bool(
            np.any(prior_weights(self._status.structure, self.memory) > 0.0)
        )

    def seed(self, prior: SeedPrior, cov: FloatArray) -> None:
        """Run from a seed's ``prior`` (``cov``: its information's inverse)."""
        status = self._status
        self.current.seed(prior, cov, self._settings.covariance_bound)
        self.errors.restart(prior.sigma2)
        self.ages.restart(status.samples)
        if status.structure.cascade:
            self._settling = settling_samples(status.structure, prior.p)
        self.mode = RUNNING
        self.ever_started = True
        self._next_solve = status.samples + self._settings.block

    def refit(self) -> None:
        """Iterate over the memory now, with the rows since the last block boundary (the
        schedule unchanged); or, before an estimate, a batch fit on the rows when enough."""
        if self.running:
            due = self._next_solve
            self.event()
            self._next_solve = due
        else:
            self.attempts.file(self.memory, *self._pending_rows())
            if len(self.memory) >= self.attempts.min_rows and not self._status.structure.cascade:
                self._initialise()

    def check(self) -> None:
        """Never iterate from a corrupted state: stop (and re-initialise) if the estimate is
        not a valid separated vector."""
        if self.running:
            why = theta_problem(self._status.structure, self.current.theta)
            if why is not None:  # e.g. a corrupted state
                self.stop(why)

    # ------------------------------------------------------------------ rows

    def _new_memory(self, width: int) -> BinnedRows:
        """An empty memory as the settings ask."""
        s = self._settings
        return BinnedRows(width, s.bins, s.branch_memory, s.region_floor)

    def piece(self, u: FloatArray, y: FloatArray, b: BoolArray, first: int) -> None:
        """Rows, errors and excitation of a stretch of samples within one block (the first
        is sample ``first``)."""
        s = self._settings
        running = self.running  # else: warming up or stopped
        rows, at = self.stream.take(
            self._status.structure,
            self.current.theta if running else None,
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
                self.pending.append((rows, stamps))
                informative[at] = 1.0
        status = self._status
        status.excitation = ewma(informative, 1.0 / s.excitation_memory, status.excitation)

    def _judge(self, rows: FloatArray, stamps: IntArray, at: IntArray, n: int) -> FloatArray:
        """A priori one-step errors of new rows at the current estimate (eqs. 24/35), kept
        for the block's end; which samples informed which block."""
        used, left, right = self.errors.judge(
            self._status.structure,
            self.current.theta,
            self.current.unit_cov,
            rows,
            ratio=self._settings.divergence_ratio,
            running=self.mode == RUNNING,  # while held, the scale holds
        )
        self.pending.append((rows, stamps))
        informative = np.zeros(n)
        informative[at[used]] = 1.0
        self.ages.note(stamps[used] + 1, left, right)
        return informative

    def _pending_rows(self) -> tuple[FloatArray, IntArray]:
        """The rows of the block, taken out of the queue."""
        if not self.pending:
            return np.empty((0, self.memory.width)), np.empty(0, dtype=np.intp)
        rows = np.concatenate([r for r, _ in self.pending])
        stamps = np.concatenate([t for _, t in self.pending])
        self.pending = []
        return rows, stamps

    # ------------------------------------------------------------------ the events

    def event(self) -> None:
        """The end of a block (running, held) or a batch-fit attempt (warming, stopped)."""
        if self.mode == RUNNING:
            self._end_block()
        elif self.mode == HELD:
            self._end_held_block()
        else:
            self._attempt()

    def _blown(self) -> bool:
        """The short-term one-step error exceeds ``divergence_ratio`` times its scale."""
        return self.errors.blown(self._settings.divergence_ratio)

    def _end_block(self) -> None:
        """File the block's rows and iterate over the memory (when it got new rows)."""
        s = self._settings
        status = self._status
        self._next_solve = status.samples + s.block
        rows, stamps = self._pending_rows()
        if self._blown():
            self.mode = HELD
            self._scale_before = self.errors.long
            self.attempts.restart(status.samples)
            if not status.structure.cascade:
                self.held_back = self._new_memory(self.memory.width)
            if self.held_back is not None:
                self.attempts.file(self.held_back, rows, stamps)
            self.why = (
                f"the one-step error blew up (RMS {math.sqrt(self.errors.short):.3g} against "
                f"a running {math.sqrt(self.errors.long):.3g}); the estimate is held and new "
                "rows are kept out of the memory"
            )
            status.reason = ""
            return
        self.attempts.file(self.memory, rows, stamps)
        if rows.shape[0]:
            self._iterate()
        if status.structure.cascade and status.samples - self._settled_at >= s.check_every:
            self._settled_at = status.samples
            self._settling = settling_samples(
                status.structure, status.structure.from_theta(self.current.theta)
            )

    def _end_held_block(self) -> None:
        """Resume when the errors are normal again; else hold the rows back and try a batch
        fit on them (backlash) or on the recent samples (cascade) when due."""
        self._next_solve = self._status.samples + self._settings.block
        rows, stamps = self._pending_rows()
        if not self._blown():
            self.mode = RUNNING
            self.held_back = None
            self._status.reason = ""
            self.attempts.file(self.memory, rows, stamps)
            if rows.shape[0]:
                self._iterate()
            return
        if self.held_back is not None:
            self.attempts.file(self.held_back, rows, stamps)
        if self._attempt_due():
            self._initialise()

    def _attempt(self) -> None:
        """File the rows since the last attempt point; a batch-fit attempt when due."""
        self.attempts.file(self.memory, *self._pending_rows())
        if self._attempt_due():
            self._initialise()
        elif not self._status.structure.cascade:
            self.attempts.next_attempt = self._status.samples + self._settings.block

    def _attempt_due(self) -> bool:
        """A backlash fits its rows once they grew by a quarter since the last attempt; the
        cascade fits its recent samples at growing intervals."""
        if self._status.structure.cascade:
            return self._status.samples >= self.attempts.next_attempt
        source = self.held_back if self.mode == HELD else self.memory
        return source is not None and self.attempts.rows_due(len(source))

    # ------------------------------------------------------------------ (re)initialisation

    def _initialise(self) -> bool:
        """Start (or restart) from a batch fit (:mod:`~genbacklash_core.online.restart`): a
        backlash on every row of its memory (or, while the errors are blown up, the rows
        held back since); the cascade on its recent samples: the whole buffer at first, the
        latest ``initial_samples`` on retried restarts. Returns whether it started."""
        s = self._settings
        status = self._status
        structure = status.structure
        attempt = self.attempts.attempted(status.samples, structure.cascade)
        span = (self.stream.low, self.stream.high)
        if structure.cascade:
            latest = self.ever_started and attempt > 0  # a retried restart: the latest only
            last = s.initial_samples if latest else s.buffer
            u, y = (a.copy() for a in self.stream.recent.window(last))
            window = (u, y, self.stream.recent.breaks(last))
            first = status.samples - self._queue.queued - u.size  # ends at the last seen
            memory = self._new_memory(self.memory.width)
            start = cascade_start(structure, status.sign_now, window, first, memory, s, span)
        else:
            source = self.held_back if self.mode == HELD else self.memory
            assert source is not None  # (_attempt_due checked it)
            self.attempts.used(len(source))
            start = backlash_start(structure, status.sign_now, source, s, span)
        if isinstance(start, str):
            status.reason = f"batch fit failed: {start}"
            return False
        sigma2 = start.solution.sigma2
        why = rejected(sigma2, self._scale_before, s.divergence_ratio, attempt)
        if why is not None:
            status.reason = why
            return False
        if self.ever_started:
            self.restarts += 1
        status.drift = None  # a new memory: refit the bands' term at once
        self.bands.restart()
        status.structure = structure = start.structure
        status.sign_now = True
        self.memory = start.memory
        self.held_back = None
        if start.lags is not None:
            self.stream.lags = start.lags
        self.current.start(start.solution, start.pull)
        self._committed()
        self.errors.restart(max(sigma2, 1e-300))
        self._scale_before = math.nan
        self.attempts.attempts = 0
        self.mode = RUNNING
        self.ever_started = True
        self._next_solve = status.samples + s.block
        self.ages.restart(status.samples)
        if structure.cascade:
            theta = start.solution.theta
            self._settling = settling_samples(structure, structure.from_theta(theta))
            self._settled_at = status.samples
        self.pending = []
        status.reason = ""
        return True

    # ------------------------------------------------------------------ the iteration

    def _iterate(self) -> None:
        """One iteration over the memory; an invalid iterate is not taken (the estimate
        holds), and ``MAX_INVALID`` of them in a row re-initialise from the memory."""
        span = (self.stream.low, self.stream.high)
        why = self.current.step(self._status.structure, self.memory, span)
        if why is None:
            self._committed()
        elif self.current.invalid >= MAX_INVALID:
            self.stop(f"{self.current.invalid} iterations in a row left the valid set ({why})")

    def _committed(self) -> None:
        """An iterate was taken: its sample, and the bands' tracking term when due."""
        self.bands.committed(self._status, self.current.theta, self.memory, self.stream.recent)

    def stop(self, why: str) -> None:
        """The estimate left the valid set: re-initialise at once from the memory (backlash)
        or the recent samples (cascade); the last valid estimate stands meanwhile."""
        self.mode = STOPPED
        self.held_back = None
        self.attempts.file(self.memory, *self._pending_rows())  # the data are sound: keep
        self._scale_before = self.errors.long
        self.attempts.attempts = 0
        self.attempts.fresh = self.attempts.need = len(self.memory)  # (the memory is due now)
        self.current.restore(self._status.structure)
        self.why = why
        self._initialise()
