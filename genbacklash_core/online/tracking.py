"""How far an online estimate trails a drivetrain that changes: the tracking term of its bands.

An online identifier fits the rows it remembers. While the drivetrain changes under it (a
gap that wears wider), those rows describe it as it was over the memory's span, and the
least-squares estimate of eq. (29) is close to the drivetrain's value at the rows' mean age,
not now. That is a bias, not noise: the statistical covariance of eq. (23) does not see it,
and while the gap moves its 2-sigma band sits beside the truth (the bundled operation bag read
``0.1034 +/- 0.0005`` rad against a true 0.1139).

:func:`dead_zone_drift` fits the remembered rows again with the dead zones ``c_L``, ``c_R``
drifting linearly with the rows' age: it gives how far the drivetrain has moved past the
estimate (``p_now - p``) and the drift rates. When a rate stands out of its noise
(:attr:`DeadZoneDrift.drifting`), the identifiers add ``b b^T`` (``b`` that distance) to the
covariance they publish: the estimate's mean squared error is ``cov + b b^T``. The estimate
itself is left as it was (what the compensator and the state use).

The same fit asks a second question: does the model misfit the data the way a servo between
the command and the gear makes it misfit? A drive that trails the command by ``tau`` ticks
reads, while moving, the branch at ``u(t) - tau (u(t) - u(t-1))``: to first order each dead
zone looks wider by ``tau |u(t) - u(t-1)|`` (eqs. 11-12: ``dR/dc_R = -R'``, ``dL/dc_L = L'``),
so the estimate of eq. (29), fitted on rows that move, sits beside the quasi-static dead zones
(the truth a slow sweep measures; on the MuJoCo drivetrains 2.6-3.7 mrad of play, ~5 %, at a
60 Hz servo). That is model error, not noise: the residuals are correlated with the speed,
and no covariance computed from their spread alone (eq. 23's, or a sandwich of it) grows with
the number of rows the way a bias does not shrink with it. So the rows are fitted once more
with a *lag* column per dead zone, ``|u(t) - u(t-1)| J_c``: its coefficient is the apparent
widening per unit of command step (a servo delay in ticks), and the fit's value at zero speed,
:attr:`DeadZoneDrift.rest`, is where the quasi-static dead zones sit, with its covariance
``C_rest``. The bands then add ``b b^T + C_rest`` with ``b`` the distance from the estimate to
that point: the estimate's mean squared error about the drivetrain at rest, ``E[(p - p_rest)
(p - p_rest)^T]``, with ``p_rest`` itself estimated -- when a lag stands out of its noise
(:attr:`DeadZoneDrift.lagging`, ``DRIFT_Z`` standard deviations), like the drift. Gated, so a
drivetrain the play operator describes keeps its statistical bands (where the model holds,
``b`` is noise and the term would be ``~2 C_rest``: wider where the band was right already,
and the seeded start of a checkpoint, whose prior is the saved covariance, would be weaker).
The price of the gate is a pre-test's: while a real lag is not yet certain (the first seconds
after convergence) the band lacks it. Only the band: the estimate (what the compensator uses)
is not moved.

What neither a drift nor a lag explains -- a spring that rings, gravity holding the load on
one flank, a servo whose error is not linear in the speed -- stays in the residual of the last
of those fits as a misfit that follows the motion. Its power is the lag-1 autocovariance of
the residuals of adjacent rows in time order (white noise has none), and the worst bias a
misfit of that size can cause is a model-error covariance ``C_model = (N e^2 / 3) (J^T J)^-1``
(:mod:`genbacklash_core.model_error`, the same term as the batch identify's, on the one-step
sensitivities ``J`` of the ``N`` rows): :attr:`DeadZoneDrift.model_covariance`. The bands add
it when that misfit stands out of its noise (:attr:`~genbacklash_core.model_error.Misfit.
significant`), so the play operator with white noise keeps its statistical bands. Only the
bands: the identifiers' state, confidence and drift detection read their own statistical
covariance.

The one-step rows hide a misfit that keeps the load off the model's flank for a whole move
(gravity holding it on one flank: the rows fit a shifted dead zone and show little misfit),
and the recursive identifier's remembered rows are rarely consecutive readings, so their
lag-1 covariance misses a misfit that follows the motion. So the fit is also given the latest
``BAND_SAMPLES`` readings the identifier took, and the estimate is run over them freely (the
play operator carrying its own state, as the batch identify's output-error residual does):
the same model-error covariance on that residual and the free run's sensitivities,
:attr:`DeadZoneDrift.free_run_covariance` (:func:`free_run_model`; the readings' rounding
taken out). The bands add both model terms (:meth:`DeadZoneDrift.model_term`); again only the
bands.

The free run asks one more question: do the rows and the readings agree on the parameters?
Where the play operator describes the drivetrain, the estimate fitted on the rows and the one
the free run over the readings would give both sit at the truth, and the step between them,
``(J^T J)^+ J^T r`` (one Gauss-Newton step of eq. 23 on the free run's sensitivities ``J`` and
residual ``r``), is noise. A servo between the command and the gear is not noise: each row
pairs a reading with a command the motor has not reached yet, so the rows see a wider play,
while the free run, which carries the load's state through each move, is pulled by the
readings the servo leaves on the flank. On the MuJoCo near_ideal drivetrain at a 60 Hz servo
the rows' play is 2.1-3.5 mrad wide of the quasi-static play, the step takes it back to
within 0.1-1.7 mrad, and the free-run misfit left after the step is no larger than the
readings' rounding (``e`` 0: no model term). When the step's play stands out of its noise
(:attr:`DeadZoneDrift.free_run_offset`; ``STEP_Z`` standard deviations, its variance a
sandwich by batch means over ``STEP_BLOCKS`` blocks of the readings, plus the estimate's
own), the bands add ``b b^T`` with ``b`` the distance from the estimate to that point: the
two disagree, and the truth may be either. Gated like the lag: where the model holds, the
step is noise and the band keeps its width. And only where the free run at the step's end
describes the readings to within one reading's step (its correlated misfit, the rounding taken
out, at most the readings' step ``q``): where a larger misfit is left (a spring that rings, a
load that coasts) the free run's optimum is the output error's best compromise, not the
drivetrain, and the model-error term bounds the bias instead (on the compliant MuJoCo
drivetrain, with the step counted there too, the play's 2-sigma band was 88-160 mrad for
errors of 0.4-2.5 mrad; without, 88-102). The batch means matter: on quantised readings
of an exact play (the operation scenario, no servo) the step's play reached 0.4 mrad, far
outside a white ``s^2 (J^T J)^+`` (the rounding stays the same through a dwell) and 2.5 of
the sandwich's standard deviations. Only the band.

The cost is one more solve of a ``(P + 2..4)``-column Gram matrix per fit of the bands, the
model-error term's pseudo-inverse of a ``P x P`` Gram matrix, and one free run with its
sensitivities over ``BAND_SAMPLES`` readings (2-8 ms on a busy machine; the recursive
identifier fits the bands once per 250 samples at most).

A backlash alone only: the cascade's bands are the statistical ones.

Examples
--------
>>> from genbacklash_core.backlash import GeneralBacklash
>>> rng = np.random.default_rng(0)
>>> u0 = rng.uniform(-1, 1, 400); u1 = u0 + rng.choice([-0.2, 0.2], 400)
>>> age = np.arange(400.0)[::-1]  # rows in time order: the first is the oldest
>>> c = 0.05 + 1e-4 * (399 - age)  # both dead zones grew by 0.04 over the rows
>>> y1 = np.where(u1 > u0, u1 - c, u1 + c)  # every row engages a branch
>>> p = np.array([1.0, 0.07, 1.0, 0.07])  # m_left_1, c_left, m_right_1, c_right: the mean
>>> fit = dead_zone_drift(Structure(1), p, (u0, u1, u0.copy(), y1), age)
>>> fit.drifting, np.round(fit.correction, 4).tolist()  # c is 0.0899 now, 0.0199 past p
(True, [0.0, 0.0199, 0.0, 0.0199])
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from genbacklash_core._typing import ArrayLike, BoolArray, FloatArray
from genbacklash_core.model_error import Misfit, correlated_misfit, model_error_covariance
from genbacklash_core.structure import Structure
from genbacklash_core.uncertainty import free_run_residual

__all__ = [
    "BAND_SAMPLES",
    "DRIFT_Z",
    "DeadZoneDrift",
    "FreeRunModel",
    "dead_zone_drift",
    "free_run_model",
    "one_step_sensitivity",
    "resolution",
    "with_tracking",
]

DRIFT_Z = 3.0  # a dead zone drifts when its rate is this many standard deviations from 0
BAND_SAMPLES = 10_000  # the recent readings the free run of the bands' model term covers
STEP_BLOCKS = 20  # blocks of the free run's readings whose spread gives its step's noise
STEP_Z = 3.0  # the free run's step counts when its play stands this many std. dev. from 0


@dataclass(frozen=True)
class FreeRunModel:
    """What the free run of an estimate over recent readings says of its model error
    (:func:`free_run_model`).

    Attributes
    ----------
    misfit : Misfit
        The correlated part of the free-run residual the parameters do not explain, the
        readings' rounding taken out.
    covariance : ndarray, shape (P, P)
        The model-error covariance ``(N e^2 / 3) (J^T J)^+`` of ``misfit`` (zeros when it is
        not significant).
    offset : ndarray, shape (P,)
        The step from the estimate to the free run's linearised optimum,
        ``(J^T J)^+ J^T r``, when its play stands ``STEP_Z`` standard deviations from zero
        (``_stands_out``) and ``misfit`` is at most one reading's step; zeros when not (the
        rows and the readings agree within noise, or the free run does not describe the
        readings).
    """

    misfit: Misfit
    covariance: FloatArray
    offset: FloatArray


@dataclass(frozen=True)
class DeadZoneDrift:
    """What a joint fit of the remembered rows with dead zones that drift says.

    Attributes
    ----------
    estimate : ndarray, shape (P,)
        The estimate ``p`` the rows were fitted around.
    correction : ndarray, shape (P,)
        ``p_now - p``: how far the drivetrain has moved past the estimate ``p`` (natural
        parameters); the estimate trails by ``-correction``.
    covariance : ndarray, shape (P, P)
        Covariance of ``correction`` (the joint fit's, drift rates included).
    rate : ndarray, shape (2,)
        Growth of ``c_left`` and ``c_right`` per clock tick.
    rate_std : ndarray, shape (2,)
        Standard deviations of ``rate``.
    rows : int
        Rows that engaged a branch (those the fit used).
    dead : tuple of int
        Where ``c_left`` and ``c_right`` sit in the parameters.
    lag : ndarray, shape (2,)
        Apparent widening of ``c_left`` and ``c_right`` per unit of command step
        ``|u(t) - u(t-1)|`` (a servo delay in ticks); zeros when the rows cannot tell (every
        row moving at one speed).
    lag_std : ndarray, shape (2,)
        Standard deviations of ``lag`` (zeros when the rows cannot tell).
    rest : ndarray, shape (P,), or None
        ``p_rest - p``: where the fit with the lag puts the drivetrain (now, when drifting)
        at zero command speed, from the estimate ``p``; None when the rows cannot tell a lag.
    rest_covariance : ndarray, shape (P, P), or None
        Covariance of ``rest``.
    misfit : Misfit or None
        The correlated part of the last fit's residuals over consecutive rows (None: not
        measured).
    model_covariance : ndarray, shape (P, P), or None
        The model error's covariance from ``misfit`` (zeros when it is not significant).
    free_run : Misfit or None
        The correlated part of the free-run residual of ``estimate`` over the recent
        readings, the rounding taken out (None: not measured: no readings given, too few,
        or a branch not engaged in them).
    free_run_covariance : ndarray, shape (P, P), or None
        The model error's covariance from ``free_run`` on the free run's sensitivities
        (zeros when it is not significant).
    free_run_offset : ndarray, shape (P,), or None
        The step from ``estimate`` to the free run's linearised optimum over the recent
        readings when it stands out of its noise, else zeros (None: not measured); see
        :class:`FreeRunModel`.
    """

    estimate: FloatArray
    correction: FloatArray
    covariance: FloatArray
    rate: FloatArray
    rate_std: FloatArray
    rows: int
    dead: tuple[int, int] = (0, 0)
    lag: FloatArray = field(default_factory=lambda: np.zeros(2))
    lag_std: FloatArray = field(default_factory=lambda: np.zeros(2))
    rest: FloatArray | None = None
    rest_covariance: FloatArray | None = None
    misfit: Misfit | None = None
    model_covariance: FloatArray | None = None
    free_run: Misfit | None = None
    free_run_covariance: FloatArray | None = None
    free_run_offset: FloatArray | None = None

    def model_term(self) -> FloatArray:
        """The model-error covariance the bands add: :attr:`model_covariance` (the one-step
        rows') plus :attr:`free_run_covariance` (the free run's); zeros when neither is
        measured.

        Each bounds the bias that the misfit its own residual shows can cause
        (:mod:`genbacklash_core.model_error`). The one-step rows restart from each measured
        reading and hide a misfit that keeps the load off the model's flank for a whole
        move (gravity, a servo's lag), which the free run accumulates; the one-step
        residual is what is left after the drift and the lag are fitted. Their sum: the
        band is never narrower than either alone (where one dominates, as on the MuJoCo
        drivetrains, the sum is close to it)."""
        size = self.correction.size
        total = np.zeros((size, size))
        for term in (self.model_covariance, self.free_run_covariance):
            if term is not None:
                total = total + term
        return np.asarray(total, dtype=np.float64)

    @property
    def lagging(self) -> bool:
        """Whether the rows show a lag beyond doubt: either dead zone's apparent widening
        with the command speed more than ``DRIFT_Z`` standard deviations from zero. The
        play operator (eqs. 20-21) is rate independent; a lag is the model's error (a servo
        between the command and the gear); the bands then add the distance to the zero-speed
        point :attr:`rest` (see the module notes)."""
        return bool(np.any(np.abs(self.lag) > DRIFT_Z * self.lag_std))

    @property
    def drifting(self) -> bool:
        """Whether either dead zone drifts beyond doubt: a rate more than ``DRIFT_Z``
        standard deviations from zero. On a drivetrain that does not change the correction
        is noise (of the order of the estimate's own standard deviation), and a band that
        added it everywhere would be wider where it was right already."""
        return bool(np.any(np.abs(self.rate) > DRIFT_Z * self.rate_std))

    def tracking_covariance(
        self, current: FloatArray | None = None, ticks: float = 0.0
    ) -> FloatArray:
        """The term the bands add to the covariance of the estimate ``current`` (default
        :attr:`estimate`) ``ticks`` after the rows were fitted.

        When :attr:`lagging`: ``b b^T + C_rest``, ``b`` the distance from ``current`` to the
        drivetrain at rest, ``estimate + rest - current`` (the dead zones ``rate * ticks``
        further when :attr:`drifting`): the mean squared error about a point that is itself
        estimated. Else, when :attr:`drifting`: ``b b^T`` with ``b = estimate + correction -
        current`` (likewise moved on). Else zeros: on a drivetrain the model describes
        ``correction`` and ``rest`` are noise, and a band that added them would be wider
        where it was right already.

        ``cov + b b^T`` is the estimate's mean squared error when ``b`` is its bias; the
        2-sigma band then reaches at least ``2 |b|`` from the estimate, room for an error in
        ``b`` as large as ``b`` itself.

        In every case plus :meth:`model_term`, the misfit neither explains (zeros when it is
        white), and ``d d^T`` with ``d = estimate + free_run_offset - current``, the distance
        to where the free run over the recent readings puts the parameters, when the rows
        and the readings disagree beyond noise (zeros when they agree)."""
        size = self.correction.size
        drifting = self.drifting
        model = self.model_term()
        if self.free_run_offset is not None and np.any(self.free_run_offset):
            d = (
                self.free_run_offset
                if current is None
                else self.estimate + self.free_run_offset - current
            )
            model = model + np.outer(d, d)
        extra = np.zeros((size, size))
        if self.lagging and self.rest is not None and self.rest_covariance is not None:
            offset, extra = self.rest, self.rest_covariance
        elif drifting:
            offset = self.correction
        else:
            return np.asarray(model, dtype=np.float64)
        b = offset if current is None else self.estimate + offset - current
        if ticks and drifting:
            b = b.copy()
            b[list(self.dead)] += self.rate * ticks
        return np.asarray(np.outer(b, b) + extra + model, dtype=np.float64)


def one_step_sensitivity(
    structure: Structure, p: FloatArray, u1: FloatArray, y0: FloatArray
) -> tuple[FloatArray, FloatArray]:
    """The play operator's one-step prediction from the measured previous state, and its
    derivative with respect to the natural parameters ``p`` (shape ``(N, P)``).

    ``x(t) = min(max(x(t-1), lo(u(t))), hi(u(t)))`` (eqs. 20-21) with ``lo``, ``hi`` the
    branches ``R(u) = sum_k m_Rk (u - c_R)^k`` and ``L(u) = sum_k m_Lk (u + c_L)^k``
    (eqs. 11-12, 16-17) in the order of the branch sense. A row that engages neither branch
    holds ``x(t-1)`` and depends on no parameter (a zero row). This is
    :func:`~genbacklash_core.refine.simulation_jacobian` restarted at every row, in one
    vectorised pass.

    >>> s = Structure(1)
    >>> x, jac = one_step_sensitivity(s, np.array([1.0, 0.1, 1.0, 0.1]),
    ...                               np.array([1.0, -1.0, 0.0]), np.array([0.0, 0.0, 0.0]))
    >>> x.tolist(), jac.tolist()  # up (R engages), down (L engages), inside the play
    ([0.9, -0.9, 0.0], [[0.0, 0.0, 0.9, -1.0], [-0.9, 1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 0.0]])
    """
    n = structure.degree
    m_left, c_left = p[:n], float(p[n])
    m_right, c_right = p[n + 1 : 2 * n + 1], float(p[2 * n + 1])
    k = np.arange(1, n + 1, dtype=np.float64)
    z_left = np.vander(u1 + c_left, n, increasing=True)  # (u + c_L)^(k-1), k = 1..n
    z_right = np.vander(u1 - c_right, n, increasing=True)
    pow_left = z_left * (u1 + c_left)[:, None]  # (u + c_L)^k: dL/dm_Lk
    pow_right = z_right * (u1 - c_right)[:, None]
    left = pow_left @ m_left  # eqs. (11), (16)
    right = pow_right @ m_right  # eqs. (12), (17)
    d_left = z_left @ (k * m_left)  # dL/dc_L
    d_right = -(z_right @ (k * m_right))  # dR/dc_R
    lo_is_right = right <= left  # increasing branches: lo = R (simulate.play_bounds)
    lo = np.where(lo_is_right, right, left)
    hi = np.where(lo_is_right, left, right)
    x = np.minimum(np.maximum(y0, lo), hi)  # eqs. (20)-(21) from the measured x(t-1)
    jac = np.zeros((u1.size, structure.n_parameters))
    by_right = np.where(y0 < lo, lo_is_right, np.where(y0 > hi, ~lo_is_right, False))
    by_left = np.where(y0 < lo, ~lo_is_right, np.where(y0 > hi, lo_is_right, False))
    jac[by_left, :n] = pow_left[by_left]
    jac[by_left, n] = d_left[by_left]
    jac[by_right, n + 1 : 2 * n + 1] = pow_right[by_right]
    jac[by_right, 2 * n + 1] = d_right[by_right]
    return np.asarray(x, dtype=np.float64), jac


def _adjacent_misfit(residual: FloatArray, age: FloatArray) -> Misfit:
    """:func:`~genbacklash_core.model_error.correlated_misfit` of the rows in time order, each
    paired with the row before it however far apart they are (the recursive identifier's
    memory keeps 1,000 rows of a long span, few of them consecutive samples). White noise
    leaves no lag-1 covariance at any spacing, so the gate holds; a misfit that follows the
    motion decorrelates over a wide spacing, so the term can only be the smaller for it."""
    order = np.argsort(-age, kind="stable")  # the oldest first
    return correlated_misfit(residual[order])


def _solve(design: FloatArray, target: FloatArray) -> tuple[FloatArray, FloatArray] | None:
    """Least squares ``design @ coef ~ target``: ``coef`` and its covariance
    ``s^2 (D^T D)^-1`` (eq. 23's form), or None when the rows cannot tell (fewer rows than
    columns, an empty column, or a direction the Gram matrix cannot resolve).

    By the normal equations of the column-scaled design: a handful of columns, so the Gram
    matrix is tiny; LAPACK's lstsq on the ~1000 x 10 design cost ~10 ms on a busy machine,
    this ~0.1 ms.
    """
    if target.size <= design.shape[1]:
        return None
    scale = np.sqrt(np.einsum("ij,ij->j", design, design))
    if not np.all(scale > 0.0):
        return None
    unit = design / scale
    gram = unit.T @ unit
    eig = np.linalg.eigvalsh(gram)
    if not eig[0] > 1e-12 * eig[-1]:
        return None
    inverse = np.linalg.inv(gram)
    coef = (inverse @ (unit.T @ target)) / scale
    left = target - design @ coef
    dof = max(target.size - design.shape[1], 1)
    s2 = float(left @ left) / dof
    return coef, s2 * inverse / np.outer(scale, scale)


def dead_zone_drift(
    structure: Structure,
    p: FloatArray,
    rows: tuple[FloatArray, FloatArray, FloatArray, FloatArray],
    age: ArrayLike,
    recent: tuple[FloatArray, FloatArray, BoolArray] | None = None,
) -> DeadZoneDrift | None:
    """Fit the remembered rows with the dead zones drifting linearly in time, then with a lag.

    A row ``(u(t-1), u(t), x(t-1), x(t))`` of age ``a`` read the drivetrain as it was then.
    With ``c_L``, ``c_R`` growing at ``rho`` per tick, its one-step prediction error at the
    estimate ``p`` (the play operator of eqs. 20-21 from the measured ``x(t-1)``) is, to first
    order, ``J (p_now - p) - a J_c rho``, where ``J`` is the prediction's sensitivity to the
    parameters (:func:`~genbacklash_core.refine.simulation_jacobian`) and ``J_c`` its columns
    of the dead zones. Least squares over the rows that engage a branch give
    ``p_now - p`` and ``rho`` together, with their covariance. None when the rows cannot
    tell (a branch without rows, fewer rows than unknowns) or for a cascade.

    Then the lag (see the module notes): the same rows with the columns
    ``|u(t) - u(t-1)| J_c`` added (the age columns only when the first fit found a drift, so
    that a drift that is not there adds no noise); its parameters' part at zero speed is
    :attr:`DeadZoneDrift.rest`. Rows that all move at one speed cannot tell a lag from the
    dead zones (the lag columns are then multiples of ``J_c``): the lag is then reported as
    zero and ``rest`` as None.

    Last the misfit neither explains: the correlated part of the last fit's residuals
    (:attr:`DeadZoneDrift.misfit`) and its model-error covariance on the rows' sensitivities;
    and, given the ``recent`` readings ``(u, y, breaks)`` in time order, the same of the
    free-run residual of ``p`` over them (:func:`free_run_model`).
    """
    if structure.cascade:
        return None
    u0, u1, y0, y1 = (np.asarray(r, dtype=np.float64) for r in rows)  # the clamp tells the branch
    if u1.size == 0:
        return None
    prediction, sens = one_step_sensitivity(structure, p, u1, y0)
    residual = y1 - prediction
    names = structure.names()
    dead = [names.index("c_left"), names.index("c_right")]
    engaged = np.any(sens != 0.0, axis=1) & np.isfinite(residual)
    sens = sens[engaged]  # the rows that engage a branch (taken once: ~1,000 x P)
    dead_columns = sens[:, dead]
    if not np.all(np.any(dead_columns, axis=0)):
        return None
    ageing = -np.asarray(age, dtype=np.float64)[engaged][:, None] * dead_columns
    target = residual[engaged]
    design = np.hstack([sens, ageing])
    drift = _solve(design, target)
    if drift is None:
        return None
    coef, cov = drift
    left = target - design @ coef
    size = p.size
    rate, rate_std = coef[size:], np.sqrt(np.maximum(np.diag(cov)[size:], 0.0))
    drifting = bool(np.any(np.abs(rate) > DRIFT_Z * rate_std))
    correction, correction_cov = coef[:size], cov[:size, :size]
    lag, lag_std = np.zeros(2), np.zeros(2)
    rest, rest_cov = None, None
    speed = np.abs(u1 - u0)[engaged][:, None]
    lagged_design = np.hstack([sens, *([ageing] if drifting else []), speed * dead_columns])
    lagged = _solve(lagged_design, target)
    if lagged is not None:
        lag_coef, lag_cov = lagged
        left = target - lagged_design @ lag_coef
        lag = lag_coef[-2:]
        lag_std = np.sqrt(np.maximum(np.diag(lag_cov)[-2:], 0.0))
        rest, rest_cov = lag_coef[:size], lag_cov[:size, :size]
    misfit = _adjacent_misfit(left, np.asarray(age, dtype=np.float64)[engaged])
    free = None if recent is None else free_run_model(structure, p, *recent, correction_cov)
    return DeadZoneDrift(
        np.array(p, dtype=np.float64),
        np.asarray(correction, dtype=np.float64),
        np.asarray(correction_cov, dtype=np.float64),
        np.asarray(rate, dtype=np.float64),
        np.asarray(rate_std, dtype=np.float64),
        int(target.size),
        (dead[0], dead[1]),
        np.asarray(lag, dtype=np.float64),
        np.asarray(lag_std, dtype=np.float64),
        None if rest is None else np.asarray(rest, dtype=np.float64),
        None if rest_cov is None else np.asarray(rest_cov, dtype=np.float64),
        misfit,
        model_error_covariance(sens, misfit),
        None if free is None else free.misfit,
        None if free is None else free.covariance,
        None if free is None else free.offset,
    )


def free_run_model(
    structure: Structure,
    p: FloatArray,
    u: FloatArray,
    y: FloatArray,
    breaks: BoolArray,
    noise: FloatArray | None = None,
) -> FreeRunModel | None:
    """The free-run misfit of ``p`` over the readings ``(u, y)`` (in time order), its
    model-error covariance ``C_model = (N e^2 / 3) (J^T J)^-1`` on the free run's
    sensitivities ``J``, and the step to the free run's linearised optimum when it stands out
    of its noise (:class:`FreeRunModel`): what the batch identify reads
    (:func:`~genbacklash_core.uncertainty.free_run_residual`: the play operator of eqs.
    20-21 run from the first reading, restarted at the sample rule's ``breaks``), with the
    readings' rounding taken out of the misfit.

    The one-step rows restart from every measured reading, so a misfit that keeps the load
    off the model's flank for a whole move (gravity pressing it on one flank, a load that
    trails the gear) leaves each row a small error, which the fit of the rows partly
    absorbs in shifted dead zones; and the recursive identifier's remembered rows are
    rarely consecutive readings (on the MuJoCo near_ideal drivetrain at a 100 Hz servo 1-2
    % of adjacent rows are one tick apart), so their lag-1 covariance misses a misfit that
    follows the motion. The free run carries the state from reading to reading: it shows
    the misfit where the rows hide it.

    The online estimate comes from the rows, not from these readings: its free-run
    residual also holds what a change of the parameters explains (the estimate's own
    statistical error, repeated at every reading of a hold as one offset, would look like
    a misfit that never averages out). So the residual is first taken at the free run's
    linearised optimum, ``r - J (J^T J)^+ J^T r``: the misfit no parameters explain, the
    one the batch identify's residual shows at its own optimum.

    The rounding of a quantised encoder on a load that moves less than a step per reading
    is not white either, but it follows the position, not the branch the load is on, and
    does not bias the dead zones the way a misfit of that size in the direction of ``J``
    could: ``q^2 / 12``, ``q`` the readings' step (:func:`resolution`; 0 for readings that
    are not quantised), is taken out of the lag-1 covariance first. The price: a real misfit
    of about one step is taken out with it (a 60 Hz servo's on the MuJoCo near_ideal
    drivetrain, which the lag term, :attr:`DeadZoneDrift.rest`, does not always cover:
    BENCHMARKS.md, issue 22). The batch identify keeps the rounding in its misfit.

    The step itself, ``(J^T J)^+ J^T r``, is where the readings would move ``p``: kept as
    :attr:`FreeRunModel.offset` when its play stands out of its noise (``noise``: the
    statistical covariance of ``p`` itself, added to the step's) and the misfit left at its
    end is at most one reading's step (see the module notes): a bias the one-step rows
    cannot see (a 60 Hz servo's on the MuJoCo near_ideal drivetrain).

    None when the readings cannot tell: a cascade, too few readings, or a parameter no
    reading informs (a branch not engaged in the window: its variance would be infinite).
    """
    if structure.cascade or u.size <= 4 * structure.n_parameters:
        return None
    residual, jac = free_run_residual(structure, p, u, y, breaks)
    informed = np.any(jac != 0.0, axis=0)
    sub = jac[:, informed]
    gram_inv = np.linalg.pinv(sub.T @ sub)
    step = gram_inv @ (sub.T @ residual)  # eq. 23's least squares on the free run's J
    # the misfit no parameters explain: the residual at the free run's linearised optimum,
    # as identify's residual is
    left = residual - sub @ step
    found = correlated_misfit(left, breaks)
    step_size = resolution(y)
    rounding = step_size**2 / 12.0  # a uniform rounding error's variance
    misfit = dataclasses.replace(found, lag_one=found.lag_one - rounding)
    cov = model_error_covariance(jac, misfit, gram=(informed, gram_inv))
    if not np.all(np.isfinite(cov)):
        return None
    offset = np.zeros(p.size)
    # the free run at the step's end describes the readings to within one reading's step:
    # its optimum is an estimate of the drivetrain, not the output error's best guess
    described = misfit.rms_model <= step_size
    if described and _stands_out(structure, informed, sub, gram_inv, step, left, noise):
        offset[informed] = step
    return FreeRunModel(misfit, cov, offset)


def _stands_out(
    structure: Structure,
    informed: BoolArray,
    jac: FloatArray,
    gram_inv: FloatArray,
    step: FloatArray,
    left: FloatArray,
    noise: FloatArray | None,
) -> bool:
    """Whether the play's part of the free run's ``step`` (``a^T (J^T J)^+ J^T r``, ``a``
    the play's direction, ``c_L + c_R``) stands ``STEP_Z`` standard deviations from zero.

    Its variance by batch means, a sandwich of eq. 23's least squares: the step is a sum
    over the readings of ``r_t J_t (J^T J)^+ a``; with the residual ``left`` at the step's
    end (what the step does not explain) in place of ``r``, summed over ``STEP_BLOCKS``
    consecutive blocks, the blocks' spread counts what a white ``s^2 (J^T J)^+`` misses (the
    rounding of a quantised encoder on a slow load stays the same for many readings). Plus
    the play's variance in ``noise``, the statistical covariance of ``p`` itself (the step
    is between two estimates)."""
    names = structure.names()
    play = np.zeros(structure.n_parameters)
    play[[names.index("c_left"), names.index("c_right")]] = 1.0
    w = np.where(np.isfinite(left), left, 0.0) * (jac @ (gram_inv @ play[informed]))
    size = w.size // STEP_BLOCKS
    if size == 0:
        return False
    blocks = w[: size * STEP_BLOCKS].reshape(STEP_BLOCKS, size).sum(axis=1)
    variance = STEP_BLOCKS * float(np.var(blocks, ddof=1)) * (w.size / (size * STEP_BLOCKS))
    if noise is not None:
        variance += float(play @ noise @ play)
    return bool(float(play[informed] @ step) ** 2 > STEP_Z**2 * variance)


def resolution(y: FloatArray) -> float:
    """The readings' step: the smallest nonzero change between two of them (0 when none).

    >>> resolution(np.array([0.0, 0.25, 0.25, 1.0, 0.5]))
    0.25
    """
    steps = np.abs(np.diff(y))
    steps = steps[steps > 0.0]
    return float(np.min(steps)) if steps.size else 0.0


def with_tracking(
    covariance: FloatArray,
    drift: DeadZoneDrift | None,
    current: FloatArray | None = None,
    ticks: float = 0.0,
) -> FloatArray:
    """The bands both identifiers publish: ``covariance`` of the estimate ``current`` plus
    the tracking term of ``drift`` ``ticks`` after it was fitted
    (:meth:`DeadZoneDrift.tracking_covariance`; ``current`` None: the estimate the drift was
    fitted around). Always a new array, also when there is no drift fit (the cascade, a
    seed): a copy of ``covariance``.

    >>> with_tracking(np.eye(2), None).tolist()
    [[1.0, 0.0], [0.0, 1.0]]
    """
    if drift is None:
        return covariance.copy()
    return covariance + drift.tracking_covariance(current, ticks)
