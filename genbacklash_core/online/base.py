"""What both online identifiers share: construction, the sample intake and the seed's start.

:class:`OnlineIdentifier` is the base of
:class:`~genbacklash_core.online.windowed.WindowedIdentifier` and
:class:`~genbacklash_core.online.recursive.RecursiveIdentifier`. It holds the parts of the
interface that are the same for both (``update(u, y) -> Estimate``, ``update_many``,
``seed``, the ``structure`` and ``estimate`` properties; :mod:`genbacklash_core.estimate`):

* **Construction.** The structure to start from and whether the branch sense is known
  (:func:`~.inputs.template`), the settings, and the input limits of the longest regression
  the identifier forms (:class:`~.inputs.InputLimits`).
* **The intake.** A sample is checked once (:func:`~.inputs.accept_sample`,
  :func:`~.inputs.checked_series`); a dropped sample breaks the chain of the sample rule
  (:mod:`genbacklash_core.samples`): the next sample taken does not follow the one before
  it. What an identifier does with the samples is its own (``_take``).
* **The seed's start** (:meth:`~OnlineIdentifier.seed`). A saved estimate becomes prior
  information (:func:`~genbacklash_core.online.seed.seed_prior`), the identifier forgets all
  samples and takes the saved structure, branch sense, sample count and excitation; each
  identifier then continues from it in its own way (``_continue_from``).
* **The status.** What the estimate is published from (structure, samples, excitation,
  reason, the bands' drift) stands in one :class:`~.status.IdentifierStatus`, made anew at
  each ``reset`` and shared with the parts the identifier is composed of.

Examples
--------
>>> import numpy as np
>>> from genbacklash_core.online import RecursiveIdentifier, WindowedIdentifier
>>> [isinstance(c(3), OnlineIdentifier) for c in (WindowedIdentifier, RecursiveIdentifier)]
[True, True]
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar, Generic, Protocol, TypeVar

import numpy as np

from genbacklash_core._typing import ArrayLike, BoolArray, FloatArray
from genbacklash_core.data import NonFinitePolicy
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.estimate import Estimate, as_sample
from genbacklash_core.structure import Structure

from .advice import AdviceCache
from .inputs import InputLimits, accept_sample, checked_series
from .seed import SeedPrior, seed_prior
from .status import IdentifierStatus

__all__ = ["OnlineIdentifier"]


class _Settings(Protocol):
    @property
    def nonfinite(self) -> NonFinitePolicy: ...


_S = TypeVar("_S", bound=_Settings)


class OnlineIdentifier(ABC, Generic[_S]):
    """The interface both online identifiers share (see the module notes).

    Parameters
    ----------
    template : (Structure, bool)
        The structure to start from and whether its branch sense is known
        (:func:`~genbacklash_core.online.inputs.template`).
    settings : WindowedSettings or RecursiveSettings
    longest : int
        Rows of the longest regression the identifier forms (the input limits).
    """

    _CHECK_FOLLOWS: ClassVar[bool] = False  # update() rejects a `follows` that is not a bool

    settings: _S
    _status: IdentifierStatus  # what the estimate is published from, shared with the parts
    _advice: AdviceCache  # the warming-up reason's excitation advice
    _break_next: bool  # a dropped sample ended the previous call
    _estimate: Estimate | None  # None: published again when asked for

    def __init__(self, template: tuple[Structure, bool], settings: _S, longest: int) -> None:
        self._template, self._sign_known = template
        self.settings = settings
        # larger samples would overflow the regression: treated like NaN (``nonfinite``)
        self._limits = InputLimits.of(self._template.degree, longest)
        self._estimate = None
        self.reset()

    @abstractmethod
    def reset(self) -> None:
        """Forget all samples and the estimate."""

    def _forget(self) -> None:
        """What :meth:`reset` forgets in both: the samples, the structure detected, the
        estimate and what it was published with."""
        self._status = IdentifierStatus(self._template, self._sign_known)
        self._break_next = False
        self._advice = AdviceCache()
        self._estimate = None

    @abstractmethod
    def _take(self, u: FloatArray, y: FloatArray, b: BoolArray) -> None:
        """Take validated samples (``b``: the sample rule's breaks, the carried one set)."""

    @abstractmethod
    def _publish(self) -> Estimate:
        """The estimate from the current internals."""

    @property
    def structure(self) -> Structure:
        """The model structure (with the detected sense once known)."""
        return self._status.structure

    @property
    def estimate(self) -> Estimate:
        """The latest estimate."""
        if self._estimate is None:
            self._estimate = self._publish()
        return self._estimate

    def update(self, u: float, y: float, *, follows: bool = True) -> Estimate:
        """Take one sample. Returns the current estimate.

        ``follows=False``: the sample does not follow the previous one on the encoder's
        clock (a lost reading in between), so no row pairs the two.
        """
        uf, yf = as_sample(u, y)
        if self._CHECK_FOLLOWS and not isinstance(follows, (bool, np.bool_)):
            raise GenBacklashError(f"follows must be True or False, got {follows!r}")
        samples = self._status.samples
        if not accept_sample(uf, yf, self._limits, self.settings.nonfinite, samples):
            self._break_next = True  # dropped: the next sample does not follow the last
            return self.estimate
        self._take_one(uf, yf, follows)
        return self.estimate

    def _take_one(self, u: float, y: float, follows: bool) -> None:
        """Take one validated sample."""
        self._intake(np.array([u]), np.array([y]), np.array([not follows]))

    def update_many(self, u: ArrayLike, y: ArrayLike, breaks: ArrayLike | None = None) -> Estimate:
        """Take a series of samples; the same as :meth:`update` on each, vectorised.

        ``breaks[k]`` True: sample ``k`` does not follow sample ``k-1`` on the encoder's clock
        (a lost reading, a gap; :func:`~genbacklash_core.samples.sample_breaks`), so no row
        pairs them; ``breaks[0]`` refers to the previous call's last sample. Default: every
        sample follows its predecessor.
        """
        uu, yy, bb, dropped_last = checked_series(
            u, y, breaks, self._limits, self.settings.nonfinite
        )
        self._intake(uu, yy, bb)  # a break pending from the previous call goes first
        if dropped_last:  # then this call's own: its last sample was dropped
            self._break_next = True
        return self.estimate

    def _intake(self, u: FloatArray, y: FloatArray, b: BoolArray) -> None:
        """Carry the break of a dropped sample to the first sample taken; then ``_take``."""
        if u.size and self._break_next:
            b = b.copy()
            b[0] = True
            self._break_next = False
        self._take(u, y, b)

    def seed(self, estimate: Estimate) -> Estimate:
        """Continue from a saved ``estimate`` (e.g. a checkpoint's) instead of a cold start.

        Forgets all samples, then takes the estimate's parameters as the current estimate.
        Its covariance and residual give the information of the data it was fitted on
        (``cov_theta = sigma^2 (Phi^T Phi)^-1``, :func:`~.seed.seed_prior`), which joins the
        next fits as a prior standing for the part of those data the new samples have not
        replaced yet, so the estimate continues smoothly, with the uncertainty it had, while
        the identifier refills. How the prior fades is each identifier's own
        (``_continue_from``: the windowed identifier by the share of its window refilled,
        the recursive one per branch, by the share of the branch's memory refilled).

        The windowed identifier's state is ``converged`` when the estimate was settled
        (converged, or frozen for lack of excitation) and its relative standard deviation is
        within ``converged_std``; otherwise ``converging``. The confidence follows from it
        as usual. Raises :class:`GenBacklashError` (the identifier unchanged) when the
        estimate cannot seed it: another structure, another branch sense than the one
        given, no valid model, or no finite covariance and residual.

        Parameters
        ----------
        estimate : Estimate
            The saved estimate; its ``samples`` (when > 0) tell how full its window was.

        Returns
        -------
        Estimate
            The new current estimate: the saved parameters and covariance. The sample
            count goes on from the estimate's ``samples``.

        Examples
        --------
        >>> from genbacklash_core import Estimate, Structure, paper_example
        >>> from genbacklash_core.online import RecursiveIdentifier, WindowedIdentifier
        >>> truth = paper_example(1).model
        >>> saved = Estimate(Structure(3), truth.parameters(), np.eye(8) * 1e-6, 0.02, 0.6,
        ...                  "converged", 0.9, 5000)
        >>> data = paper_example(1).generate(seed=1, n_samples=600)
        >>> for kind in (WindowedIdentifier, RecursiveIdentifier):
        ...     ident = kind(degree=3)
        ...     est = ident.seed(saved)
        ...     seeded = ident.from_seed
        ...     after = ident.update_many(data.u, data.y)
        ...     error = np.max(np.abs(after.parameters - truth.parameters()))
        ...     print(est.state.value, est.model == truth, seeded, after.state.value, error < 0.02)
        converged True True converged True
        converged True True converged True
        """
        prior = self._restart_from(estimate)
        self._continue_from(prior, estimate)
        return self.estimate

    @property
    @abstractmethod
    def from_seed(self) -> bool:
        """True while the estimate still leans on a seed (:meth:`seed`)."""

    @abstractmethod
    def _continue_from(self, prior: SeedPrior, estimate: Estimate) -> None:
        """Continue from the seed's ``prior`` (``estimate``: the saved estimate) in the
        identifier's own way, after :meth:`_restart_from`."""

    def _restart_from(self, estimate: Estimate) -> SeedPrior:
        """The seed's start (see the module notes): the saved estimate as prior information,
        all samples forgotten, the saved structure, sample count and excitation taken.
        Raises :class:`GenBacklashError` (the identifier unchanged) when it cannot seed."""
        prior = seed_prior(self._template, self._sign_known, estimate)
        self._check_seed(prior)
        self.reset()
        saved = estimate.structure
        self._status.structure = Structure(saved.degree, saved.na, saved.nb, saved.sign)
        self._status.sign_now = True
        self._status.samples = estimate.samples
        self._status.excitation = estimate.excitation
        self._status.drift = None  # the saved covariance carries the saved bands
        return prior

    def _check_seed(self, prior: SeedPrior) -> None:
        """Raise :class:`GenBacklashError` when ``prior`` cannot seed this identifier."""
