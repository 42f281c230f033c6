"""What an online identifier publishes from, shared by the parts it is composed of.

An identifier (:class:`~genbacklash_core.online.base.OnlineIdentifier`) is a thin class over
parts that each hold one concept (a fit schedule, a fitter, a queue, a block machine). Those
parts read and move a few facts that the published
:class:`~genbacklash_core.estimate.Estimate` is built from: the structure (its branch sense
once detected), the samples taken, the running excitation, why the estimate is what it is,
and the bands' tracking term. :class:`IdentifierStatus` holds them once; the identifier and
its parts share the one object, made anew at each ``reset``.

Examples
--------
>>> from genbacklash_core.structure import Structure
>>> status = IdentifierStatus(Structure(3), sign_now=False)
>>> status.samples, status.reason, status.drift is None
(0, 'warming up', True)
>>> status.excitation = 1.2
>>> status.published_excitation
1.0
"""

from __future__ import annotations

from dataclasses import dataclass

from genbacklash_core.structure import Structure

from .tracking import DeadZoneDrift

__all__ = ["IdentifierStatus"]


@dataclass
class IdentifierStatus:
    """The facts an identifier publishes from (mutable; see the module notes).

    Attributes
    ----------
    structure : Structure
        The model structure, with the detected branch sense once known.
    sign_now : bool
        Whether the branch sense is known (given, or detected by a fit).
    samples : int
        Samples taken (a seed goes on from its estimate's count).
    excitation : float
        The running excitation the estimate reports.
    reason : str
        Why the estimate is what it is (each identifier words it its own way).
    drift : DeadZoneDrift or None
        The tracking term of the bands (:mod:`genbacklash_core.online.tracking`).
    """

    structure: Structure
    sign_now: bool
    samples: int = 0
    excitation: float = 0.0
    reason: str = "warming up"
    drift: DeadZoneDrift | None = None

    @property
    def published_excitation(self) -> float:
        """The excitation as an estimate reports it: within [0, 1]."""
        return min(max(self.excitation, 0.0), 1.0)
