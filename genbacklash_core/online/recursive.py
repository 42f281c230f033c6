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

This module holds the identifier itself, a composition of parts that stand in the sibling
modules of :mod:`genbacklash_core.online` (see there), one concept each: the queue
(:mod:`~.queue`), the blocks (when to file rows, iterate, hold or re-initialise;
:mod:`~.blocks`, with :mod:`~.attempts`, :mod:`~.ages` and :mod:`~.bands`), what it
publishes (:mod:`~.publish`), and the interface it shares with the windowed identifier
(:mod:`~.base`; the seed's start, :mod:`~.seed`).
"""

from __future__ import annotations

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.estimate import Estimate

from .advice import BranchCoverage, coverage_of, excitation_advice
from .base import OnlineIdentifier
from .blocks import BlockMachine
from .covariance import scaled_inverse
from .inputs import settings_or_default, template
from .memory import BinnedRows
from .publish import MemoryPublication
from .queue import SampleQueue
from .seed import SeedPrior
from .settings import RecursiveSettings

__all__ = ["RecursiveIdentifier", "RecursiveSettings"]


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
        return self._machine.restarts

    @property
    def memory(self) -> BinnedRows:
        """The rows the estimate rests on (read only; see :class:`BinnedRows`)."""
        return self._machine.memory

    @property
    def coverage(self) -> BranchCoverage:
        """How much of the input range each branch's rows cover (the memory and the rows of
        the current block), for diagnostics and reports."""
        memory = self._machine.memory
        rows, _ = memory.rows()
        if self._machine.pending:
            rows = np.concatenate([rows, *(r for r, _ in self._machine.pending)])
        return coverage_of(rows[:, 0], rows[:, 1], self.settings.bins, memory.per_direction)

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
        machine = self._machine
        rows = len(machine.memory)
        need = 0 if machine.ever_started else max(machine.attempts.min_rows - rows, 0)
        cover = self.coverage
        seen = bool(cover.up.sum() + cover.down.sum()) or machine.stream.high > machine.stream.low
        queued = self._queue.moved()
        if not seen and queued:
            return ""  # the samples are not looked at before the first attempt
        return excitation_advice(cover, moved=seen or queued, rows_needed=need)

    @property
    def from_seed(self) -> bool:
        """True while the estimate still leans on a seed (:meth:`seed`): the memory has not
        refilled a branch since (and no re-initialisation replaced the seed)."""
        return self._machine.from_seed

    def reset(self) -> None:
        """Forget all samples and the estimate."""
        self._forget()
        self._queue = SampleQueue()  # samples not seen yet
        self._machine = BlockMachine(self._status, self.settings, self._queue)
        self._current = self._machine.current  # theta, its information, its version
        self._publication = MemoryPublication(self._status, self.settings, self._machine)

    def _continue_from(self, prior: SeedPrior, estimate: Estimate) -> None:
        """Continue from a seed (:meth:`seed`): its parameters (eq. 34 inverted) as the
        current estimate; its information joins each iteration as a prior weighted by the
        share of the memory the new rows have not refilled yet (per branch). A cascade
        waits for the samples that determine its internal ``x`` (the play operator started
        from any state agrees) before it takes rows."""
        cov = scaled_inverse(prior.information)
        assert cov is not None  # (_check_seed)
        self._machine.seed(prior, cov)
        self._status.reason = f"seeded from a saved estimate ({estimate.state.value})"

    def _check_seed(self, prior: SeedPrior) -> None:
        if scaled_inverse(prior.information) is None:  # seed_prior checked that it is
            raise GenBacklashError("cannot seed: the estimate's information is singular")

    def refit(self) -> Estimate:
        """Iterate over the memory now, with the rows since the last block boundary, instead
        of at the next one (for a final estimate at the end of a record). The schedule is
        unchanged; :meth:`update` and :meth:`update_many` no longer agree exactly after it."""
        self._flush()
        self._machine.refit()
        self._estimate = None
        return self.estimate

    def _take(self, u: FloatArray, y: FloatArray, b: BoolArray) -> None:
        """Queue validated samples; process the queue at each of the schedule's events."""
        self._estimate = None
        if u.size == 0:
            return
        machine, status = self._machine, self._status
        machine.check()
        for count in self._queue.take(u, y, b, lambda: machine.due - status.samples):
            status.samples += count
            if status.samples >= machine.due:
                self._flush()
                machine.event()

    def _flush(self) -> None:
        """Process the queued samples (rows, errors, excitation) in one piece."""
        piece = self._queue.flush(self._status.samples)
        if piece is not None:
            self._machine.piece(*piece)

    def _publish(self) -> Estimate:
        return self._publication.current(self._advice, self.excitation_advice)
