"""The augmented model as a flat parameter vector: simulation, Jacobian and validity.

Layout: the base model's natural parameters (:class:`~genbacklash_core.structure.Structure`),
then, when present, ``offset``, ``drift rate``, ``saturation low``, ``saturation high``, the
input lag's pole, and a periodic error's period and ``cos_1, sin_1, .., cos_K, sin_K``. The
dead time, the drift basis and the number of harmonics are structural (not fitted by gradient
steps).

The Jacobian generalises :mod:`genbacklash_core.refine`: while a branch is engaged the backlash
output is the branch value, so its sensitivity is the branch derivative; while it holds, the
sensitivity is the one at the last engagement. With a drifting gap the branch derivative in
``k`` is the one in ``c`` times ``s(t)``. With an input lag the branch derivative in its pole
``a`` is the branch slope times ``dv/da``, which obeys ``dv/da(t) = a dv/da(t-1) + v(t-1) -
u(t-d)``; a periodic error scales every sensitivity of the load position by ``1 + E'(z)``.

Lost readings (the sample rule, :mod:`genbacklash_core.samples`): the fits pass ``anchors``,
the samples after a break, where the simulation of a model without linear dynamics restarts
at the measured output, as :func:`~genbacklash_core.refine.refine_parameters` does -- the
inputs of the lost readings are unknown, so the state cannot be carried across them. A model
with linear dynamics simulates on through (its state cannot be read off one output).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.backlash import evaluate_branch
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.play import play_operator
from genbacklash_core.samples import restart_points
from genbacklash_core.simulate import play_bounds
from genbacklash_core.structure import Structure

from .model import (
    MAX_LAG_POLE,
    AugmentedModel,
    Drift,
    DriftBasis,
    PeriodicError,
    Saturation,
    drift_coordinate,
)
from .physics import LoadPhysics

__all__ = ["ModelSpec", "SimulationOutput", "anchors_of", "shift_input"]


anchors_of = restart_points  # the samples a fit restarts its simulation at


class SimulationOutput(NamedTuple):
    """Backlash output ``x``, pre-limit output ``y_free = z + o + E(z)`` and output ``y``;
    ``z = G x`` the load position (None when it is ``x``)."""

    x: FloatArray
    y_free: FloatArray
    y: FloatArray
    z: FloatArray | None = None

    @property
    def load(self) -> FloatArray:
        """The load position ``z``."""
        return self.x if self.z is None else self.z


def shift_input(u: FloatArray, delay: int) -> FloatArray:
    """``u(t - d)``, holding ``u[0]`` before the first sample.

    >>> shift_input(np.array([1.0, 2.0, 3.0]), 1).tolist()
    [1.0, 1.0, 2.0]
    """
    if delay == 0:
        return u
    out = np.empty_like(u)
    head = min(delay, u.size)
    out[:head] = u[0]
    out[head:] = u[: u.size - head]
    return out


@dataclass(frozen=True)
class ModelSpec:
    """Structure of an :class:`AugmentedModel`: what is fitted and how it is laid out.

    Examples
    --------
    >>> from genbacklash_core import GeneralBacklash
    >>> model = AugmentedModel(GeneralBacklash.ideal(1.0, 0.2, 0.3), offset=0.1)
    >>> spec = ModelSpec.of(model)
    >>> spec.names()
    ('m_left_1', 'c_left', 'm_right_1', 'c_right', 'offset')
    >>> spec.model(spec.vector(model)) == model
    True
    """

    structure: Structure
    delay: int = 0
    offset: bool = False
    drift: DriftBasis | None = None
    saturation: tuple[bool, bool] = (False, False)
    input_lag: bool = False
    harmonics: int = 0
    physics: LoadPhysics | None = None
    input_lag_order: int = 1
    input_lag_fraction: float = 0.0

    @classmethod
    def of(cls, model: AugmentedModel) -> ModelSpec:
        """The spec of an existing model (an offset of exactly 0 counts as absent)."""
        return cls(
            Structure.of(model.base),
            model.delay,
            model.offset != 0.0,
            None if model.drift is None else model.drift.basis,
            (False, False) if model.saturation is None else model.saturation.sides,
            model.input_lag != 0.0,
            0 if model.periodic is None else model.periodic.harmonics,
            model.physics,
            model.input_lag_order,
            model.input_lag_fraction,
        )

    @property
    def n_parameters(self) -> int:
        """Length of the flat vector."""
        return (
            self.structure.n_parameters
            + int(self.offset)
            + int(self.drift is not None)
            + sum(self.saturation)
            + int(self.input_lag)
            + (1 + 2 * self.harmonics if self.harmonics else 0)
        )

    @property
    def n_free(self) -> int:
        """Free parameters for information criteria: the vector plus a dead time, its
        fraction of a sample and the load physics' parameters when present."""
        physics = 0 if self.physics is None else self.physics.n_free
        fraction = int(self.input_lag and self.input_lag_fraction > 0.0)
        return self.n_parameters + int(self.delay > 0) + fraction + physics

    def names(self) -> tuple[str, ...]:
        """Parameter names in vector order."""
        names = list(self.structure.names())
        if self.offset:
            names.append("offset")
        if self.drift is not None:
            names.append("drift_rate")
        if self.saturation[0]:
            names.append("saturation_low")
        if self.saturation[1]:
            names.append("saturation_high")
        if self.input_lag:
            names.append("input_lag_pole")
        if self.harmonics:
            names.append("period")
            for j in range(1, self.harmonics + 1):
                names += [f"cos_{j}", f"sin_{j}"]
        return tuple(names)

    def _index(self) -> tuple[int | None, int | None, int | None, int | None]:
        k = self.structure.n_parameters
        slots: list[int | None] = []
        for present in (self.offset, self.drift is not None, *self.saturation):
            slots.append(k if present else None)
            k += int(present)
        return slots[0], slots[1], slots[2], slots[3]

    def _extra_index(self) -> tuple[int | None, int | None]:
        """Where the input lag's pole and the periodic error's period sit (or None)."""
        k = self.structure.n_parameters + int(self.offset) + int(self.drift is not None)
        k += sum(self.saturation)
        i_lag = k if self.input_lag else None
        k += int(self.input_lag)
        return i_lag, (k if self.harmonics else None)

    def vector(self, model: AugmentedModel) -> FloatArray:
        """Flat parameters of ``model`` (which must have this spec's structure)."""
        theta = np.empty(self.n_parameters)
        theta[: self.structure.n_parameters] = model.base.parameters()
        i_off, i_drift, i_low, i_high = self._index()
        if i_off is not None:
            theta[i_off] = model.offset
        if i_drift is not None:
            theta[i_drift] = 0.0 if model.drift is None else model.drift.rate
        sat = model.saturation
        if i_low is not None:
            theta[i_low] = sat.low if sat is not None and sat.low is not None else np.nan
        if i_high is not None:
            theta[i_high] = sat.high if sat is not None and sat.high is not None else np.nan
        self._put_extras(theta, model)
        return theta

    def _put_extras(self, theta: FloatArray, model: AugmentedModel) -> None:
        """Write the input lag and periodic error of ``model`` (neutral when it has none: a
        pole 0, coefficients 0 and a NaN period the caller must set)."""
        i_lag, i_period = self._extra_index()
        if i_lag is not None:
            theta[i_lag] = model.input_lag
        if i_period is not None:
            periodic = model.periodic
            theta[i_period : i_period + 1 + 2 * self.harmonics] = 0.0
            theta[i_period] = np.nan if periodic is None else periodic.period
            if periodic is not None:
                k = min(periodic.harmonics, self.harmonics)
                theta[i_period + 1 : i_period + 1 + 2 * k : 2] = periodic.cos[:k]
                theta[i_period + 2 : i_period + 2 + 2 * k : 2] = periodic.sin[:k]

    def model(self, theta: FloatArray) -> AugmentedModel:
        """The validated model object for ``theta``."""
        i_off, i_drift, i_low, i_high = self._index()
        base = self.structure.model(theta[: self.structure.n_parameters])
        saturation = None
        if i_low is not None or i_high is not None:
            saturation = Saturation(
                None if i_low is None else float(theta[i_low]),
                None if i_high is None else float(theta[i_high]),
            )
        drift = None
        if i_drift is not None and self.drift is not None:
            drift = Drift(float(theta[i_drift]), self.drift)
        i_lag, _ = self._extra_index()
        lag = 0.0 if i_lag is None else float(theta[i_lag])
        return AugmentedModel(
            base,
            self.delay,
            0.0 if i_off is None else float(theta[i_off]),
            drift,
            saturation,
            lag,
            self.periodic_error(theta),
            self.physics,
            self.input_lag_order,
            self.input_lag_fraction if lag != 0.0 else 0.0,  # no lag: no servo to carry it
        )

    # ------------------------------------------------------------------ pieces

    def _parts(
        self, theta: FloatArray
    ) -> tuple[FloatArray, float, float, float | None, float | None]:
        i_off, i_drift, i_low, i_high = self._index()
        return (
            theta[: self.structure.n_parameters],
            0.0 if i_off is None else float(theta[i_off]),
            0.0 if i_drift is None else float(theta[i_drift]),
            None if i_low is None else float(theta[i_low]),
            None if i_high is None else float(theta[i_high]),
        )

    def coordinate(self, u: FloatArray) -> FloatArray | None:
        """The drift coordinate ``s(t)`` of the record, or None without drift."""
        return None if self.drift is None else drift_coordinate(u, self.drift)

    def _gain(self, p: FloatArray) -> float:
        if not self.structure.cascade:
            return 1.0
        a, b = self.structure.linear_part(p)
        den = 1.0 + float(np.sum(b))
        gain = float(np.sum(a)) / den if den != 0.0 else 0.0
        return gain if np.isfinite(gain) and abs(gain) > 1e-9 else 1.0

    def problem(
        self, theta: FloatArray, u_range: tuple[float, float], s_max: float = 0.0
    ) -> str | None:
        """Why ``theta`` is not a valid model on the data, or None when it is."""
        if not np.all(np.isfinite(theta)):
            return "a parameter became non-finite"
        p, _, rate, low, high = self._parts(theta)
        checked = p
        if self.drift is not None and rate * s_max < 0.0:
            # The branches are closest where the gap is smallest (eqs. 11-12 move apart as
            # c grows): check the validity there.
            checked = p.copy()
            n = self.structure.degree
            checked[n] += rate * s_max
            checked[2 * n + 1] += rate * s_max
        problem = self.structure.problem(checked, u_range)
        if problem is not None:
            return problem
        if low is not None and high is not None and not low < high:
            return f"the saturation limits are not ordered (low={low:.3g}, high={high:.3g})"
        i_lag, i_period = self._extra_index()
        if i_lag is not None and not 0.0 <= theta[i_lag] <= MAX_LAG_POLE:
            return f"the input lag's pole left [0, {MAX_LAG_POLE}] ({theta[i_lag]:.4g})"
        if i_period is not None and not theta[i_period] > 0.0:
            return f"the period of the periodic error is not positive ({theta[i_period]:.3g})"
        return None

    def delayed_input(self, u: FloatArray) -> FloatArray:
        """The input delayed by the dead time and, with an input lag, by its fraction of a
        sample: ``(1 - f) u(t - d) + f u(t - d - 1)``."""
        ud = shift_input(u, self.delay)
        f = self.input_lag_fraction if self.input_lag else 0.0
        if f == 0.0:
            return ud
        return (1.0 - f) * ud + f * shift_input(u, self.delay + 1)

    def backlash_input(self, theta: FloatArray, u: FloatArray) -> FloatArray:
        """``v``: the input delayed by the dead time and lagged by the input lag (if any;
        ``input_lag_order`` equal first-order stages, after its fraction of a sample)."""
        ud = self.delayed_input(u)
        i_lag, _ = self._extra_index()
        if i_lag is None:
            return ud
        a = float(theta[i_lag])
        if a == 0.0:
            return ud
        return self._stages(a, ud)[-1]

    def _stages(self, a: float, ud: FloatArray) -> list[FloatArray]:
        """Each stage's output of the input lag: ``v_k(t) = a v_k(t-1) + (1 - a)
        v_{k-1}(t)``, ``v_0 = u(t-d)``, every stage at rest at ``u(-d)`` at the start."""
        from scipy import signal  # here: a slow import most runs never need

        stages = [ud]
        for _ in range(self.input_lag_order):
            v, _ = signal.lfilter([1.0 - a], [1.0, -a], stages[-1], zi=[a * float(ud[0])])
            stages.append(np.asarray(v, dtype=np.float64))
        return stages

    def _input_sensitivity(self, theta: FloatArray, u: FloatArray, v: FloatArray) -> FloatArray:
        """``dv/da``, stage by stage: ``dv_k(t) = a dv_k(t-1) + v_k(t-1) - v_{k-1}(t) + (1 -
        a) dv_{k-1}(t)``, 0 at the start (``v`` is the last stage's output)."""
        from scipy import signal  # here: a slow import most runs never need

        i_lag, _ = self._extra_index()
        a = 0.0 if i_lag is None else float(theta[i_lag])
        ud = self.delayed_input(u)
        stages = self._stages(a, ud) if self.input_lag_order > 1 else [ud, v]
        dv = np.zeros(ud.size)
        for before, after in itertools.pairwise(stages):
            after_prev = np.concatenate([[float(ud[0])], after[:-1]])
            drive = after_prev - before + (1.0 - a) * dv
            dv = np.asarray(signal.lfilter([1.0], [1.0, -a], drive), dtype=np.float64)
        return dv

    def unread(self, theta: FloatArray, readings: FloatArray) -> FloatArray:
        """The load position ``z`` a reading ``r = z + o + E(z)`` comes from (the fixed point
        ``z = r - o - E(z)``, a few iterations: the periodic error is small)."""
        _, offset, _, _, _ = self._parts(theta)
        z = np.asarray(readings, dtype=np.float64) - offset
        periodic = self.periodic_error(theta)
        if periodic is None:
            return z
        base = z
        for _ in range(3):
            z = base - periodic(z)
        return z

    def periodic_error(self, theta: FloatArray) -> PeriodicError | None:
        """The periodic error of ``theta`` (None without one)."""
        _, i_period = self._extra_index()
        if i_period is None:
            return None
        coefficients = theta[i_period + 1 : i_period + 1 + 2 * self.harmonics]
        return PeriodicError(
            float(theta[i_period]),
            tuple(float(c) for c in coefficients[0::2]),
            tuple(float(c) for c in coefficients[1::2]),
        )

    # ------------------------------------------------------------------ simulation

    def simulate(
        self,
        theta: FloatArray,
        u: FloatArray,
        y_start: float | None = None,
        anchors: BoolArray | None = None,
        y: FloatArray | None = None,
    ) -> SimulationOutput:
        """Free-run simulation of the model ``theta`` on input ``u``.

        The backlash state starts at ``x0 = (y_start - o) / G(1)`` (0 when ``y_start`` is
        None) and a linear block at its steady state for ``x0``. Without a linear block the
        backlash state restarts at ``y - o`` where ``anchors`` is True (see the module
        notes; ``y`` the measured output).
        """
        from scipy import signal  # here: a slow import most runs never need

        p, offset, rate, low, high = self._parts(theta)
        structure = self.structure
        ud = self.backlash_input(theta, u)
        m_left, c_left, m_right, c_right = structure.split(p)
        s = self.coordinate(u)
        if s is None:
            left, right = structure.branches(p, ud)  # eqs. (11)-(12), (16)-(17)
        else:
            grow = rate * s  # c(t) = c + k s(t)
            left = evaluate_branch(m_left, ud + (c_left + grow))
            right = evaluate_branch(m_right, ud - (c_right + grow))
        x0 = (
            0.0
            if y_start is None
            else float(self.unread(theta, np.array([y_start]))[0]) / self._gain(p)
        )
        lo, hi = play_bounds(left, right)
        pinned = None
        if anchors is not None and y is not None and not structure.cascade:
            pinned = anchors
            lo, hi = lo.copy(), hi.copy()
            lo[anchors] = hi[anchors] = self.unread(theta, y[anchors])  # pin x to the reading
        if self.physics is None:
            x = play_operator(lo, hi, x0)  # eq. (20)
        else:  # the load's own motion on eq. (20)'s interval (:mod:`.physics`)
            x = self.physics.simulate(lo, hi, x0, pinned)
        if structure.cascade:
            a, b = structure.linear_part(p)
            num = np.concatenate([[0.0], a])
            den = np.concatenate([[1.0], b])
            zi = signal.lfilter_zi(num, den) * x0 if x0 != 0.0 else None
            if zi is None:
                y_lin = np.asarray(signal.lfilter(num, den, x), dtype=np.float64)  # eq. (30)
            else:
                y_lin = np.asarray(signal.lfilter(num, den, x, zi=zi)[0], dtype=np.float64)
        else:
            y_lin = x
        y_free = y_lin + offset
        periodic = self.periodic_error(theta) if self.harmonics else None
        if periodic is not None:
            y_free = y_free + periodic(y_lin)  # E(z): periodic in the load position
        y = y_free
        if low is not None or high is not None:
            y = np.clip(y_free, -np.inf if low is None else low, np.inf if high is None else high)
        return SimulationOutput(x, y_free, y, y_lin if structure.cascade else None)

    def engaged(
        self, theta: FloatArray, u: FloatArray, out: SimulationOutput, y_start: float | None
    ) -> tuple[BoolArray, BoolArray]:
        """Where the left and where the right branch is engaged (eqs. 18-19), as booleans."""
        structure = self.structure
        p, _offset, rate, _, _ = self._parts(theta)
        m_left, c_left, m_right, c_right = structure.split(p)
        ud = self.backlash_input(theta, u)
        s = self.coordinate(u)
        grow = 0.0 if s is None else rate * s
        left = evaluate_branch(m_left, ud + (c_left + grow))
        right = evaluate_branch(m_right, ud - (c_right + grow))
        x0 = (
            0.0
            if y_start is None
            else float(self.unread(theta, np.array([y_start]))[0]) / self._gain(p)
        )
        x_prev = np.concatenate([[x0], out.x[:-1]])
        f1 = (left - x_prev) * structure.sign <= 0.0  # eq. (18)
        f2 = ((x_prev - right) * structure.sign <= 0.0) & ~f1  # eq. (19)
        return f1, f2

    # ------------------------------------------------------------------ Jacobian

    def _backlash_sensitivity(
        self,
        theta: FloatArray,
        u: FloatArray,
        x: FloatArray,
        x0: float,
        anchors: BoolArray | None = None,
    ) -> tuple[FloatArray, BoolArray]:
        """``dx/d(backlash parameters[, drift rate][, input lag pole])``, shape
        (N, 2n+2[+1][+1]), column-major.

        Also returns where no branch has engaged since the start or the last anchor (the
        output still holds the measurement it was pinned to).
        """
        structure = self.structure
        p, _, rate, _, _ = self._parts(theta)
        n = structure.degree
        m_left, c_left, m_right, c_right = structure.split(p)
        ud = self.backlash_input(theta, u)
        s = self.coordinate(u)
        grow = 0.0 if s is None else rate * s
        xi1 = ud + (c_left + grow)  # eq. (16)
        xi2 = ud - (c_right + grow)  # eq. (17)
        left = evaluate_branch(m_left, xi1)
        right = evaluate_branch(m_right, xi2)
        x_prev = np.concatenate([[x0], x[:-1]])
        f1 = (left - x_prev) * structure.sign <= 0.0  # eq. (18): left branch engaged
        f2 = ((x_prev - right) * structure.sign <= 0.0) & ~f1  # eq. (19)
        pinned = np.zeros(u.size, dtype=bool) if anchors is None else anchors
        if anchors is not None:
            f1 &= ~pinned
            f2 &= ~pinned
        last = np.where(f1 | f2 | pinned, np.arange(u.size), -1)
        np.maximum.accumulate(last, out=last)  # the last engagement (or pin) at or before t
        source = np.where(last < 0, 0, last)
        never = (last < 0) | pinned[source]
        columns = structure.n_backlash + int(s is not None) + int(self.input_lag)
        jac = np.empty((u.size, columns), order="F")
        # The output holds the value of the last engaged branch: every column is a value at
        # ``source``. Gather the inputs there once and compute the columns on the gathered
        # samples (the same products, element by element, as computing then gathering).
        left_on = f1[source] & ~never
        right_on = f2[source] & ~never
        xi1 = xi1[source]
        xi2 = xi2[source]

        def held(value: FloatArray, on: BoolArray, column: int) -> None:
            jac[:, column] = 0.0  # where that branch is not the one held
            np.copyto(jac[:, column], value, where=on)

        power1 = np.ones_like(xi1)
        power2 = np.ones_like(xi2)
        dleft = np.zeros_like(xi1)
        dright = np.zeros_like(xi2)
        for i in range(1, n + 1):
            dleft += i * m_left[i - 1] * power1  # dL/dc_L
            dright -= i * m_right[i - 1] * power2  # dR/dc_R
            power1 = power1 * xi1
            power2 = power2 * xi2
            held(power1, left_on, i - 1)  # dL/dm_Li = xi1^i
            held(power2, right_on, n + i)  # dR/dm_Ri = xi2^i
        held(dleft, left_on, n)
        held(dright, right_on, 2 * n + 1)
        if s is not None:  # d/dk: the c-derivative times s(t) on whichever branch is engaged
            s_held = s[source]
            held(dleft * s_held, left_on, structure.n_backlash)
            np.copyto(jac[:, structure.n_backlash], dright * s_held, where=right_on)
        if self.input_lag:  # d/da: the branch slope in its input (eqs. 16-17) times dv/da
            dv = self._input_sensitivity(theta, u, ud)[source]
            held(dleft * dv, left_on, columns - 1)
            np.copyto(jac[:, columns - 1], -dright * dv, where=right_on)
        return jac, never

    def jacobian(
        self,
        theta: FloatArray,
        u: FloatArray,
        out: SimulationOutput,
        y_start: float | None,
        anchors: BoolArray | None = None,
    ) -> FloatArray:
        """``dy/dtheta`` of the free-run simulation ``out`` (the start state held fixed;
        ``anchors`` as in :meth:`simulate`, whose pinned states are held fixed too)."""
        from scipy import signal  # here: a slow import most runs never need

        structure = self.structure
        p, _offset, _, low, high = self._parts(theta)
        x0 = (
            0.0
            if y_start is None
            else float(self.unread(theta, np.array([y_start]))[0]) / self._gain(p)
        )
        pins = None if structure.cascade else anchors
        jx, never = self._backlash_sensitivity(theta, u, out.x, x0, pins)
        jac = np.zeros((u.size, self.n_parameters), order="F")
        n_bl = structure.n_backlash
        i_off, i_drift, i_low, i_high = self._index()
        i_lag, i_period = self._extra_index()
        extra = [(i, j) for i, j in ((i_drift, n_bl), (i_lag, jx.shape[1] - 1)) if i is not None]
        if structure.cascade:
            a, b = structure.linear_part(p)
            num = np.concatenate([[0.0], a])
            den = np.concatenate([[1.0], b])
            for col in range(n_bl):
                jac[:, col] = signal.lfilter(num, den, jx[:, col])  # (A/B) dx/dp
            for col, source in extra:  # drift rate, input lag pole
                jac[:, col] = signal.lfilter(num, den, jx[:, source])
            y_lin = out.load  # z = G x (without the periodic error)
            col = n_bl
            for i in range(2, structure.na + 1):
                shifted = np.zeros_like(out.x)
                shifted[i:] = out.x[:-i]
                jac[:, col] = signal.lfilter([1.0], den, shifted)  # dy/da_i
                col += 1
            for j in range(1, structure.nb + 1):
                shifted = np.zeros_like(y_lin)
                shifted[j:] = y_lin[:-j]
                jac[:, col] = -signal.lfilter([1.0], den, shifted)  # dy/db_j
                col += 1
        else:
            jac[:, :n_bl] = jx[:, :n_bl]
            for col, source in extra:
                jac[:, col] = jx[:, source]
        periodic = self.periodic_error(theta)
        if periodic is not None and i_period is not None:
            z = out.load
            slope = np.zeros_like(z)
            for j in range(1, periodic.harmonics + 1):
                w = 2.0 * np.pi * j / periodic.period
                c, s = periodic.cos[j - 1], periodic.sin[j - 1]
                cos_wz, sin_wz = np.cos(w * z), np.sin(w * z)
                slope += w * (s * cos_wz - c * sin_wz)  # E'(z)
                jac[:, i_period + 2 * j - 1] = cos_wz  # dE/dcos_j
                jac[:, i_period + 2 * j] = sin_wz  # dE/dsin_j
                jac[:, i_period] += (c * sin_wz - s * cos_wz) * (w * z / periodic.period)  # dE/dP
            load = [k for k in range(i_period) if k not in (i_off, i_low, i_high)]
            jac[:, load] *= (1.0 + slope)[:, None]  # dy/dz dz/dtheta
        if i_off is not None:
            jac[:, i_off] = 1.0
            if not structure.cascade:
                jac[never, i_off] = 0.0  # x0 = y_start - o: the output holds y_start
        if low is not None or high is not None:
            clipped_low = out.y_free < low if low is not None else np.zeros(u.size, dtype=bool)
            clipped_high = out.y_free > high if high is not None else np.zeros(u.size, dtype=bool)
            jac[clipped_low | clipped_high, :] = 0.0
            if i_low is not None:
                jac[clipped_low, i_low] = 1.0
            if i_high is not None:
                jac[clipped_high, i_high] = 1.0
        return jac

    def extended(
        self,
        *,
        degree: int | None = None,
        orders: tuple[int, int] | None = None,
        delay: int | None = None,
        offset: bool | None = None,
        drift: DriftBasis | None = None,
        saturation: tuple[bool, bool] | None = None,
        input_lag: bool | None = None,
        harmonics: int | None = None,
        physics: LoadPhysics | None = None,
        input_lag_order: int | None = None,
        input_lag_fraction: float | None = None,
    ) -> ModelSpec:
        """A spec with some parts replaced (``orders`` is ``(na, nb)``)."""
        s = self.structure
        na, nb = (s.na, s.nb) if orders is None else orders
        return ModelSpec(
            Structure(s.degree if degree is None else degree, na, nb, s.sign),
            self.delay if delay is None else delay,
            self.offset if offset is None else offset,
            self.drift if drift is None else drift,
            self.saturation if saturation is None else saturation,
            self.input_lag if input_lag is None else input_lag,
            self.harmonics if harmonics is None else harmonics,
            self.physics if physics is None else physics,
            self.input_lag_order if input_lag_order is None else input_lag_order,
            self.input_lag_fraction if input_lag_fraction is None else input_lag_fraction,
        )

    def embed(self, model: AugmentedModel) -> FloatArray:
        """Parameters of ``model`` placed in this (larger) spec; new parts start neutral.

        Higher branch coefficients and linear terms start at 0, an offset at the model's,
        a drift rate, an input lag's pole and harmonic coefficients at 0. Saturation limits
        and a new period have no neutral value and must be set by the caller (they are NaN
        here).
        """
        old = ModelSpec.of(model)
        s_new, s_old = self.structure, old.structure
        if s_new.sign != s_old.sign:
            raise GenBacklashError("cannot embed a model of the other branch sense")
        if s_new.degree < s_old.degree:
            raise GenBacklashError(
                f"cannot embed a degree-{s_old.degree} model in degree {s_new.degree}"
            )
        theta = np.full(self.n_parameters, np.nan)
        p_old = model.base.parameters()
        n_old, n_new = s_old.degree, s_new.degree
        p = np.zeros(s_new.n_parameters)
        p[:n_old] = p_old[:n_old]  # m_left
        p[n_new] = p_old[n_old]  # c_left
        p[n_new + 1 : n_new + 1 + n_old] = p_old[n_old + 1 : 2 * n_old + 1]  # m_right
        p[2 * n_new + 1] = p_old[2 * n_old + 1]  # c_right
        if s_new.cascade and s_old.cascade:
            a_old, b_old = s_old.linear_part(p_old)
            a = np.zeros(s_new.na)
            b = np.zeros(s_new.nb)
            a[: min(a.size, a_old.size)] = a_old[: a.size]
            b[: min(b.size, b_old.size)] = b_old[: b.size]
            p[s_new.n_backlash : s_new.n_backlash + s_new.na - 1] = a[1:]
            p[s_new.n_backlash + s_new.na - 1 :] = b
        theta[: s_new.n_parameters] = p
        i_off, i_drift, i_low, i_high = self._index()
        if i_off is not None:
            theta[i_off] = model.offset
        if i_drift is not None:
            theta[i_drift] = 0.0 if model.drift is None else model.drift.rate
        sat = model.saturation
        if i_low is not None and sat is not None and sat.low is not None:
            theta[i_low] = sat.low
        if i_high is not None and sat is not None and sat.high is not None:
            theta[i_high] = sat.high
        self._put_extras(theta, model)
        return theta
