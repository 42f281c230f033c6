"""A saved estimate as prior information: how both identifiers continue from a checkpoint.

After a restart an identifier can continue from a saved
:class:`~genbacklash_core.estimate.Estimate` instead of a cold start (``seed``). The
estimate's covariance and residual give the information of the data it rested on: with
``cov_theta = sigma^2 (Phi^T Phi)^-1`` (the covariance of eqs. 23/33, carried back from the
natural parameters through eq. 34 by the delta method), ``Phi^T Phi`` is the information
of the regression rows behind it, in units of rows. :func:`seed_prior` checks the estimate
and computes that information once, for both identifiers; each then lets it fade in its
own way as new data replace it (the windowed identifier by the share of the window the new
samples or rows filled, :class:`WindowSeed`; the recursive one per branch, by the share of
the branch's memory refilled, :func:`prior_weights`), since what "replaced" means depends
on how each remembers.

Examples
--------
>>> from genbacklash_core import Estimate, Structure, paper_example
>>> truth = paper_example(1).model
>>> saved = Estimate(Structure(3), truth.parameters(), np.eye(8) * 1e-6, 0.02, 0.6,
...                  "converged", 0.9, 5000)
>>> prior = seed_prior(Structure(3), False, saved)
>>> bool(np.allclose(prior.p, truth.parameters())), prior.information.shape
(True, (8, 8))
>>> prior.scaled(0.5).rows == prior.rows / 2
True
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.estimate import Estimate
from genbacklash_core.structure import Structure

from .covariance import scaled_inverse, theta_jacobian
from .memory import BinnedRows

__all__ = ["SeedPrior", "WindowSeed", "prior_weights", "seed_prior"]


@dataclass(frozen=True)
class SeedPrior:
    """A saved estimate as prior information for the regression (internal).

    ``information`` is the ``Phi^T Phi`` the estimate's covariance implies
    (``cov_theta = sigma2 (Phi^T Phi)^-1``, the covariance of eqs. 23/33), in units of
    regression rows, so that it adds to the information of new rows; ``rows`` is how many
    engaged rows it stands for and ``sigma2`` their equation-error variance.
    """

    p: FloatArray
    theta: FloatArray
    information: FloatArray
    sigma2: float
    rows: float

    def scaled(self, weight: float) -> SeedPrior:
        """The same prior standing for ``weight`` times as many rows."""
        return SeedPrior(
            self.p, self.theta, self.information * weight, self.sigma2, self.rows * weight
        )


@dataclass(frozen=True)
class WindowSeed:
    """A seed the windowed identifier's window still leans on (internal): its ``prior``, the
    ``samples`` of the window it stands for, and the feed's ``progress`` when it was planted.

    >>> from genbacklash_core import Estimate, Structure, paper_example
    >>> saved = Estimate(Structure(3), paper_example(1).model.parameters(), np.eye(8) * 1e-6,
    ...                  0.02, 0.6, "converged", 0.9, 5000)
    >>> seed = WindowSeed(seed_prior(Structure(3), False, saved), samples=1500, progress=0)
    >>> seed.weight(kept=600), seed.weight(kept=-5)
    (0.4, 0.0)
    """

    prior: SeedPrior
    samples: int
    progress: int

    def weight(self, kept: int) -> float:
        """Share of the seed's samples still counted, ``kept`` of them not replaced yet."""
        return max(kept, 0) / self.samples


def seed_prior(template: Structure, sign_known: bool, estimate: Estimate) -> SeedPrior:
    """The prior information of a saved ``estimate`` for an identifier of ``template``.

    Raises :class:`GenBacklashError` when the estimate cannot seed it: not an
    :class:`Estimate`, another degree or linear order, another branch sense than a known one,
    no valid model, or no usable uncertainty (a non-finite or non-positive residual, a
    covariance that is not finite and positive definite).
    """
    if not isinstance(estimate, Estimate):
        raise GenBacklashError(f"cannot seed from {estimate!r}: not an Estimate")
    saved = estimate.structure
    if (saved.degree, saved.na, saved.nb) != (template.degree, template.na, template.nb):
        raise GenBacklashError(
            f"cannot seed: the estimate has degree {saved.degree}, na {saved.na}, nb "
            f"{saved.nb}; the identifier degree {template.degree}, na {template.na}, nb "
            f"{template.nb}"
        )
    if sign_known and saved.sign != template.sign:
        raise GenBacklashError(
            f"cannot seed: the estimate's branch sense {saved.sign:+g} is not the "
            f"identifier's {template.sign:+g}"
        )
    if estimate.model is None:
        raise GenBacklashError("cannot seed: the estimate holds no valid model")
    sigma2 = estimate.residual * estimate.residual  # inf, not OverflowError, when huge
    if not (math.isfinite(sigma2) and sigma2 > 0.0):
        raise GenBacklashError(
            f"cannot seed: the estimate's residual {estimate.residual!r} is not a positive number"
        )
    p = np.array(estimate.parameters, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):  # checked just below
        theta = saved.theta(p)  # eq. (23): products m c may overflow float64
    if not np.all(np.isfinite(theta)):
        raise GenBacklashError(
            "cannot seed: the estimate's parameters are too large to use (their products "
            "overflow float64)"
        )
    inverse = scaled_inverse(np.array(estimate.covariance, dtype=np.float64))
    bad = "cannot seed: the estimate's covariance is not finite and positive definite"
    if inverse is None:
        raise GenBacklashError(bad)
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # cholesky checks
        jac = theta_jacobian(saved, theta)
        information = sigma2 * (jac.T @ inverse @ jac)  # (cov_theta / sigma2)^-1, delta method
        information = 0.5 * (information + information.T)
    try:
        np.linalg.cholesky(information)
    except np.linalg.LinAlgError as err:
        raise GenBacklashError(bad) from err
    n = saved.degree
    # the f1 and -f2 columns of eq. (22) are +-1 on engaged rows: their squares count them
    rows = float(information[1, 1] + information[n + 2, n + 2])
    if not sigma2 * max(rows, 1.0) <= 1e200:  # the fits add it to sums of squares
        raise GenBacklashError(
            f"cannot seed: the estimate's residual {estimate.residual!r} and covariance are "
            "too large to use (the information they stand for overflows float64)"
        )
    return SeedPrior(p, theta, information, sigma2, max(rows, 1.0))


def prior_weights(structure: Structure, memory: BinnedRows) -> FloatArray:
    """Per parameter, the share of a seed's information the recursive identifier still
    counts: one minus the share of the branch's ``memory`` (of the whole memory, for the
    linear block) refilled since the seed. (The windowed identifier fades its seed as one
    scalar share of its window instead: it forgets by window, not by branch.)

    >>> from genbacklash_core.online.memory import BinnedRows
    >>> memory = BinnedRows(width=6, bins=2, per_direction=4, floor=1)
    >>> prior_weights(Structure(1), memory).tolist()
    [1.0, 1.0, 1.0, 1.0]
    """
    n1 = structure.degree + 1
    down, up = memory.direction_counts()
    per_direction = memory.capacity / 2
    w = np.empty(structure.n_parameters)
    w[:n1] = max(0.0, 1.0 - down / per_direction)
    w[n1 : 2 * n1] = max(0.0, 1.0 - up / per_direction)
    w[2 * n1 :] = max(0.0, 1.0 - (down + up) / memory.capacity)
    return w
