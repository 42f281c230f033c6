"""A simulated record of normal operation and its truth (:class:`OperationRecord`)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.samples import bridge_lost, sample_breaks

from .settings import HiddenEffects, OperationSettings


@dataclass(frozen=True, eq=False)
class OperationRecord:
    """A simulated record and its truth.

    Attributes
    ----------
    settings : OperationSettings
    seed : int
    command_t_ns, command_u : ndarray
        Command times (ns from the start) and values, radians.
    sample_t_ns : ndarray of int
        Every encoder sampling instant, lost readings included (the stamps).
    u_all : ndarray
        The held command at each sampling instant (the backlash input).
    x_all : ndarray
        The noise-free load position at each instant.
    y_all : ndarray
        The reading the encoder makes at each instant (noise, quantisation).
    received : ndarray of bool
        Readings that arrive (the others are lost).
    c_left, c_right : ndarray
        The true dead zones at each instant (they change with wear).
    phase_starts : tuple of (str, float)
        Each phase's kind and start, seconds.
    hidden : HiddenEffects or None
        The effects beyond the backlash the record was made with (``x_all`` is then the
        output before noise, not the backlash output).
    """

    settings: OperationSettings
    seed: int
    command_t_ns: IntArray
    command_u: FloatArray
    sample_t_ns: IntArray
    u_all: FloatArray
    x_all: FloatArray
    y_all: FloatArray
    received: BoolArray
    c_left: FloatArray
    c_right: FloatArray
    phase_starts: tuple[tuple[str, float], ...] = field(default=())
    hidden: HiddenEffects | None = None

    @property
    def truth(self) -> GeneralBacklash:
        """The drivetrain at the start."""
        return self.settings.model

    def truth_at(self, index: int) -> GeneralBacklash:
        """The drivetrain at sample ``index`` (wear included)."""
        m = self.settings.model
        return GeneralBacklash(
            m.m_left, float(self.c_left[index]), m.m_right, float(self.c_right[index])
        )

    @property
    def truth_end(self) -> GeneralBacklash:
        """The drivetrain at the end."""
        return self.truth_at(self.sample_t_ns.size - 1)

    @property
    def encoder_t_ns(self) -> IntArray:
        """Stamps of the readings that arrive."""
        return self.sample_t_ns[self.received]

    @property
    def encoder_y(self) -> FloatArray:
        """The readings that arrive."""
        return self.y_all[self.received]

    def series(self, *, bridge: bool = False) -> tuple[FloatArray, FloatArray, BoolArray]:
        """``(u, y, breaks)`` as the node sees it: one sample per reading that arrived, the
        input the command held at its stamp, and the sample rule's breaks
        (:func:`~genbacklash_core.samples.sample_breaks`).

        With ``bridge``, the breaks that lost readings caused along a monotone input are
        lifted (:func:`~genbacklash_core.samples.bridge_lost`): right for a backlash alone,
        as the node does with ``model: backlash``; not for linear dynamics after it.
        """
        period = 1e9 / self.settings.encoder_rate
        breaks = sample_breaks(self.encoder_t_ns, period)
        if bridge:
            breaks = bridge_lost(breaks, self.u_all, np.flatnonzero(self.received))
        return self.u_all[self.received], self.y_all[self.received], breaks
