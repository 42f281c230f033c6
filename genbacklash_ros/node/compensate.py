"""The compensate stage: a command and the estimate in use in, the command to send out.

:class:`CompensateStage` owns the :class:`~genbacklash_core.InverseBacklash` of the node. It
is created at the first model (the load where the encoder saw it last, the motor at the
last command sent), takes each new model the identify stage adopts (:meth:`adopt`, right
after the result arrives, so a command rarely pays for the inversion plan of a new model)
and compensates one command per call (:meth:`command`, one compensator step: tens of
microseconds). While a fault is active it passes the command through (confidence 0: the
output and rate limits still hold); without a model it only limits. Whatever it is given,
what it returns is finite.

Examples
--------
>>> from genbacklash_core import CompensatorOptions, Estimate, Structure
>>> stage = CompensateStage(CompensatorOptions(u_max=1.0), compensate=True)
>>> stage.command(2.0, Estimate.empty(Structure(3)), passing=lambda: False, last_y=None)
1.0
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from genbacklash_core import (
    CompensatorOptions,
    Estimate,
    GenBacklashError,
    GuardVerdict,
    InverseBacklash,
)
from genbacklash_core.measured import TrackingVerdict

__all__ = ["CompensateStage", "CompensationStatus"]


@dataclass(frozen=True, slots=True)
class CompensationStatus:
    """Whether the node compensates now, how much, and why (``/diagnostics``, reports).

    Attributes
    ----------
    weight : float
        The share of the inverse applied, in ``[0, 1]``.
    state : str
        ``"on"`` (weight 1), ``"faded"`` or ``"off"`` (weight 0).
    reason : str
        Why: compensation switched off, no estimate, a fault passing commands through, the
        estimate's confidence below the gate, or the guard's judgement
        (:class:`~genbacklash_core.GuardVerdict`).
    """

    weight: float
    state: str
    reason: str


def _no_fault() -> bool:
    """No fault is active (the batch form runs commands only then)."""
    return False


class CompensateStage:
    """The node's compensator and its limits (see the module notes).

    Parameters
    ----------
    options : CompensatorOptions
    compensate : bool
        False: every command is sent as it is (no limits either).
    """

    def __init__(self, options: CompensatorOptions, *, compensate: bool) -> None:
        self._options = options
        self._on = compensate
        self._comp: InverseBacklash | None = None
        self._comp_estimate: Estimate | None = None
        # the compensation guard's trust in [0, 1] (genbacklash_core.guard), a factor on the
        # estimate's confidence: compensation fades out where it does not help
        self.trust = 1.0
        # the measured tracking's share in [0, 1] (genbacklash_core.measured), a factor on
        # the weight itself: a trial at up to half weight, off where compensating tracked worse
        self.share = 1.0
        self.last_sent: float | None = None
        self.last_weight = 0.0  # the share of the inverse in the last command sent
        self.problems: list[str] = []  # why a model was not taken (the caller reports them)

    @property
    def options(self) -> CompensatorOptions:
        """The options in use."""
        return self._options

    def weight(self, est: Estimate) -> float:
        """How much of the inverse is applied at ``est``'s confidence (0 without a model)."""
        if not self._on or est.model is None:
            return 0.0
        return self._options.weight(self._confidence(est.confidence))

    def _confidence(self, confidence: float) -> float:
        """The confidence the compensator is given for an estimate's ``confidence``: scaled
        by the guard's trust, then moved so that the weight it gives is scaled by
        :attr:`share`."""
        opts = self._options
        c = confidence * self.trust
        if self.share >= 1.0:
            return c
        w = opts.weight(c) * max(self.share, 0.0)
        if w <= 0.0:
            return 0.0
        return opts.gate_low + w * (opts.gate_high - opts.gate_low)

    def status(
        self,
        est: Estimate,
        faults: tuple[str, ...],
        guard: GuardVerdict,
        measured: TrackingVerdict | None = None,
    ) -> CompensationStatus:
        """How much the next command is compensated with ``est`` while ``faults`` (names)
        pass commands through, ``guard`` being the guard's verdict and ``measured`` the
        measured tracking's (:mod:`genbacklash_core.measured`), and why."""
        if not self._on:
            return CompensationStatus(0.0, "off", "compensation switched off (compensate: false)")
        if est.model is None:
            return CompensationStatus(0.0, "off", "no estimate yet")
        if faults:
            names = ", ".join(name.replace("_", " ") for name in faults)
            return CompensationStatus(0.0, "off", f"a fault passes commands through: {names}")
        weight = self.weight(est)
        state = "on" if weight >= 1.0 else "off" if weight <= 0.0 else "faded"
        parts = []
        if self._options.weight(est.confidence) < 1.0:
            parts.append(
                f"the estimate's confidence {est.confidence:.2f} is below gate_high "
                f"{self._options.gate_high:g}"
            )
        if guard.state != "judging" and (guard.trust < 1.0 or state == "on"):
            parts.append(guard.reason)
        if measured is not None and (
            measured.state in ("faded", "off", "probing") or measured.trust < 1.0
        ):  # (trust below 1 while judging: a trial's weight, or held off until measured)
            parts.append(measured.reason)
        return CompensationStatus(weight, state, "; ".join(parts) or f"compensation {state}")

    def command(
        self, value: float, est: Estimate, *, passing: Callable[[], bool], last_y: float | None
    ) -> float:
        """The command to send for the desired ``value`` with the estimate ``est``
        (``passing()``: a fault is active; asked only when a model compensates)."""
        sent = self._command(value, est, passing, last_y)
        self.last_sent = sent
        return sent

    def commands(self, values: list[float], est: Estimate, *, last_y: float | None) -> list[float]:
        """:meth:`command` for each of ``values`` in turn with no fault active (the batch
        form): the same commands, in one call to the compensator."""
        comp = self._comp
        if not values:
            return []
        if not self._on or comp is None or est is not self._comp_estimate:
            return [self.command(v, est, passing=_no_fault, last_y=last_y) for v in values]
        confidence = self._confidence(est.confidence)
        sent = comp.steps(values, confidence)
        self.last_weight = self._options.weight(confidence)
        for k, command in enumerate(sent):
            if not math.isfinite(command):  # as _command: within the limits instead
                if k:
                    self.last_sent = sent[k - 1]
                sent[k] = self._limit(values[k])
        self.last_sent = sent[-1]
        return sent

    def _command(
        self, value: float, est: Estimate, passing: Callable[[], bool], last_y: float | None
    ) -> float:
        self.last_weight = 0.0
        if not self._on:
            return value
        if est is not self._comp_estimate:
            self._refresh(est, value, last_y)
        comp = self._comp
        if comp is None:
            return self._limit(value)
        confidence = 0.0 if passing() else self._confidence(est.confidence)
        sent = comp.step(value, confidence)
        if not math.isfinite(sent):
            return self._limit(value)
        self.last_weight = self._options.weight(confidence)
        return sent

    def ready(self, est: Estimate) -> bool:
        """True when :meth:`command` with ``est`` needs no new model (the batch form runs
        only such commands; a new model is taken by the per-message path)."""
        return not self._on or est is self._comp_estimate

    def adopt(self, est: Estimate, last_y: float | None) -> None:
        """A new estimate is in use: prepare the compensator for it now."""
        if self._on and est is not self._comp_estimate:
            self._refresh(est, None, last_y)

    def _refresh(self, est: Estimate, value: float | None, last_y: float | None) -> None:
        """Give the compensator the model of ``est`` (creating it at the first model). A
        model that cannot be inverted keeps the previous one."""
        self._comp_estimate = est
        model = est.model
        if model is None:
            return
        comp = self._comp
        try:
            if comp is None:
                # the load where the encoder saw it last (else where it is wanted), the
                # motor at the last command sent (else mid-gap: the load at rest)
                opts = self._options
                x0 = last_y if last_y is not None else value
                if x0 is None:
                    return
                last = self.last_sent
                u0 = None if last is None else min(max(last, opts.u_min), opts.u_max)
                self._comp = InverseBacklash(model, opts, x0, u0)
            elif model != comp.model:
                comp.set_model(model)
        except GenBacklashError as err:
            self.problems.append(f"compensator kept its previous model: {err}")

    def _limit(self, value: float) -> float:
        """Pass-through within the output limits and the rate limit (no model yet)."""
        opts = self._options
        u = value
        last = self.last_sent
        if last is not None:
            u = min(max(u, last - opts.max_rate), last + opts.max_rate)
        return min(max(u, opts.u_min), opts.u_max)

    def reconfigure(self, options: CompensatorOptions, *, compensate: bool) -> None:
        """New options (the compensator keeps its state) or compensation switched."""
        comp = self._comp
        old = self._options
        self._options = options
        self._on = compensate
        if comp is not None and old != options:
            state = comp.state
            u0 = min(max(state.u, options.u_min), options.u_max)
            try:
                self._comp = InverseBacklash(comp.model, options, state.x, u0)
            except GenBacklashError as err:
                self.problems.append(f"compensator restarted: {err}")
                self._comp, self._comp_estimate = None, None
        if not compensate:  # re-initialised from the latest measurement when re-enabled
            self._comp, self._comp_estimate = None, None

    def restart(self) -> None:
        """Forget the compensator and the last command (identification restarted)."""
        self._comp, self._comp_estimate = None, None
        self.last_sent = None
