"""Recursive least squares over the paper's regressors, guarded for long unattended runs.

The parameter vector is the separated one of eqs. (23)/(33); each sample gives one regressor row
(eq. 22, or eq. 32 for the cascade) whose internal variables -- the switching functions
(eqs. 27-28), ``xi`` (eqs. 25-26) and, for the cascade, the internal output ``x`` of eq. (36),
propagated sample by sample -- are evaluated with the current estimate. Started cold, such a
recursion converges slowly and can diverge (GUIDE §2), so :class:`RecursiveIdentifier`

* starts from a short batch fit (the paper's iteration on the first ``initial_samples``), whose
  information matrix ``Phi^T Phi`` becomes the prior information ``R``;
* forgets per branch and per sample of time: a row that engages the left branch discounts only
  the left branch's information, by ``(1 - lambda) / s`` where ``s`` is the running share of
  samples engaging that branch, so every branch (and the linear block, per moving sample)
  remembers about ``1 / (1 - lambda)`` samples however often it is engaged;
* forgets only the information above a floor ``R_0 = R_init / covariance_bound``, so the
  covariance never exceeds ``covariance_bound`` times its initial value (no wind-up);
* freezes -- no update, no forgetting -- on samples without information: no branch engaged
  (backlash alone), an input that does not move, or (cascade) a resting ``x`` whose linear
  response has settled;
* freezes a block of parameters (a branch, or the linear block) while the recent input sweeps
  too little of it to identify it (a coverage test on the recent information matrix, see
  ``min_conditioning``): its rows are skipped and its parameters held, since fitting a
  polynomial to a narrow part of its range would bend the whole branch to that part;
* detects divergence -- non-finite estimate, a slope or dead zone of the wrong sign, an invalid
  model (crossing branches, unstable linear block), a one-step error that blows up against its
  running scale -- and re-initialises from a batch fit over its buffered recent window.

One update, in information form, for rows ``Phi`` with targets ``z`` (eqs. 24 / 35) and the
diagonal forgetting ``D`` (``sqrt`` of each parameter's block factor)::

    R <- D (R - R_0) D + R_0 + Phi^T Phi
    theta <- theta + R^-1 Phi^T (z - Phi theta)

:meth:`RecursiveIdentifier.update` applies it to each sample's row.
:meth:`RecursiveIdentifier.update_many` applies it to blocks of ``block`` samples: their
regressors are computed with the block-start estimate and their forgetting is lumped. With
``block=1`` the two agree to rounding; with longer blocks they differ in how soon the
switching decisions see the newest estimate and in the guards running at block ends only (a
small fraction of the parameter uncertainty, see the tests).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import signal

from ._typing import ArrayLike, BoolArray, FloatArray
from .data import NonFinitePolicy, scale_limits
from .errors import GenBacklashError, NonFiniteInputError
from .estimate import (
    Estimate,
    EstimatorState,
    as_sample,
    as_series,
    check_setting,
    confidence_of,
    relative_std_of,
)
from .identify import _backlash_columns, _switching
from .play import play_operator
from .simulate import play_bounds
from .structure import Structure
from .windowed import (
    FitFailure,
    SampleRing,
    WindowFit,
    _merge_index,
    block_conditioning,
    cold_fit,
    conditioning_floor,
    fit_window,
    natural_covariance,
    natural_from_theta,
    natural_variances,
    parameter_blocks,
    samples_since_change,
    scaled_inverse,
    seed_prior,
    settling_samples,
)

__all__ = ["RecursiveIdentifier", "RecursiveSettings"]

_SHORT_MEMORY = 20.0  # informative samples in the short residual average (divergence test)
_LONG_MEMORY = 1000.0  # informative samples in the long residual average (its scale)
_INIT_ITERATIONS = 10  # warm iterations on the initial window after the cold start
_MAX_REJECTIONS = 8  # restarts that may be rejected for a poor fit before any fit is taken
_MIN_SHARE = 0.25  # floor of a branch's engagement share in the per-row forgetting
_MAX_FORGETTING = 0.5  # at most half a block's information per row

# rows, targets; flags per sample: row used, left engaged, right engaged, input moved
_BlockRows = tuple[FloatArray, FloatArray, BoolArray, BoolArray, BoolArray, BoolArray]


@dataclass(frozen=True)
class RecursiveSettings:
    """Settings of :class:`RecursiveIdentifier` (validated on construction).

    Attributes
    ----------
    forgetting : float
        ``lambda`` in ``[0.5, 1]``, per sample of time: each branch (and the linear block)
        remembers about ``1 / (1 - lambda)`` samples, so a drifting parameter is tracked with a
        lag of about that many samples; smaller tracks faster and is noisier. 1 forgets
        nothing.
    initial_samples : int
        Samples of the batch fit that starts the recursion (>= 20).
    buffer : int
        Recent samples kept for re-initialisation after a divergence (>= ``initial_samples``).
    block : int
        Samples per block in :meth:`RecursiveIdentifier.update_many` (1 to 4096): longer is
        cheaper per sample; the regressors of a block use the block-start estimate.
    covariance_bound : float
        Only the information above ``R_init / covariance_bound`` is forgotten, so the
        covariance never exceeds this multiple of its value after the batch fit.
    input_deadband : float
        The input counts as moving when a step exceeds this fraction of the input span of the
        initial window; samples where it does not move do not update anything.
    excitation_memory : int
        Memory, in samples, of the running informative share reported as ``excitation`` and
        of the recent information matrix behind the coverage test (``min_conditioning``).
    min_excitation : float
        Below this informative share the state is ``no_excitation``.
    min_conditioning : float
        A block of parameters (left branch, right branch, linear block) is frozen while the
        smallest eigenvalue of its normalised recent information matrix is below this
        fraction of its value at the start: the input then sweeps too little of the branch
        to identify its polynomial, and updating would only fit that small part.
    min_linear_conditioning : float
        The same for the linear block of a cascade. Higher, because a slow input makes
        ``x`` and ``y`` nearly collinear and the noisy ``y`` in the regressors then biases
        the equation error strongly; random input keeps it above ~0.8 of its reference.
    divergence_ratio : float
        Divergence when the short-term RMS one-step error exceeds this multiple of its
        long-term value.
    check_every : int
        Samples between full validity checks (crossing branches, linear stability) and
        coverage tests.
    converged_std : float
        ``converged`` needs every parameter's standard deviation below
        ``converged_std * max(1, max|p|)``; also the confidence scale.
    nonfinite : {"raise", "drop"}
        NaN/inf samples, and samples too large for the regression (beyond
        :func:`~genbacklash_core.data.scale_limits`), raise, or are skipped.

    Notes
    -----
    Measured on the paper's Example 1 (random input, SNR 25): the default
    (``forgetting=0.998``) tracks a linearly growing gap ~500 samples behind, 0.999 ~1000;
    over a million samples with resting, dithering and narrow-sweep stretches it never
    diverged. ``update_many`` costs a few microseconds per sample; ``update`` some tens.

    Examples
    --------
    >>> RecursiveSettings(forgetting=0.999).block
    64
    >>> RecursiveSettings(forgetting=1.5)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: forgetting must lie in [0.5, 1], got 1.5
    """

    forgetting: float = 0.998
    initial_samples: int = 300
    buffer: int = 1000
    block: int = 64
    covariance_bound: float = 20.0
    input_deadband: float = 1e-4
    excitation_memory: int = 200
    min_excitation: float = 0.02
    min_conditioning: float = 0.03
    min_linear_conditioning: float = 0.3
    divergence_ratio: float = 5.0
    check_every: int = 100
    converged_std: float = 0.02
    nonfinite: NonFinitePolicy = "raise"

    def __post_init__(self) -> None:
        check_setting("forgetting", self.forgetting, 0.5, 1.0, whole=False)
        check_setting("initial_samples", self.initial_samples, 20, 10_000_000, whole=True)
        check_setting("buffer", self.buffer, self.initial_samples, 100_000_000, whole=True)
        check_setting("block", self.block, 1, 4096, whole=True)
        check_setting("covariance_bound", self.covariance_bound, 1.0, math.inf, whole=False)
        check_setting("input_deadband", self.input_deadband, 0.0, 1.0, whole=False)
        check_setting("excitation_memory", self.excitation_memory, 1, 10_000_000, whole=True)
        check_setting("min_excitation", self.min_excitation, 0.0, 1.0, whole=False)
        check_setting("min_conditioning", self.min_conditioning, 0.0, 1.0, whole=False)
        check_setting(
            "min_linear_conditioning", self.min_linear_conditioning, 0.0, 1.0, whole=False
        )
        check_setting("divergence_ratio", self.divergence_ratio, 1.0, math.inf, whole=False)
        check_setting("check_every", self.check_every, 1, 10_000_000, whole=True)
        check_setting("converged_std", self.converged_std, 1e-12, math.inf, whole=False)
        if self.nonfinite not in ("raise", "drop"):
            raise GenBacklashError(f"nonfinite must be 'raise' or 'drop', got {self.nonfinite!r}")


class RecursiveIdentifier:
    """Recursive least squares with per-branch forgetting over the paper's regressors.

    Parameters
    ----------
    degree : int
        Polynomial degree of each branch.
    na, nb : int
        Linear block orders (eq. 30); ``na = 0`` (default) identifies a backlash alone.
    sign : {+1, -1, None}
        Branch sense; None detects it at the initial batch fit.
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
        if sign is not None and sign not in (1, -1):
            raise GenBacklashError(f"sign must be +1, -1 or None (detect), got {sign!r}")
        self._template = Structure(degree, na, nb, 1.0 if sign is None else float(sign))
        self._sign_known = sign is not None
        if settings is None:
            settings = RecursiveSettings()
        if not isinstance(settings, RecursiveSettings):
            raise GenBacklashError(f"settings must be RecursiveSettings, got {settings!r}")
        self.settings = settings
        # larger samples would overflow the regression: treated like NaN (``nonfinite``)
        self._u_limit, self._y_limit = scale_limits(self._template.degree, settings.buffer)
        self._estimate: Estimate | None = None
        self.reset()

    # ------------------------------------------------------------------ public interface

    @property
    def structure(self) -> Structure:
        """The model structure (with the detected sense once known)."""
        return self._structure

    @property
    def estimate(self) -> Estimate:
        """The latest estimate."""
        if self._estimate is None:
            self._estimate = self._build_estimate()
        return self._estimate

    @property
    def restarts(self) -> int:
        """How many times the recursion was re-initialised after a divergence."""
        return self._restarts

    def reset(self) -> None:
        """Forget all samples and the estimate."""
        s = self.settings
        size = self._template.n_parameters
        self._ring = SampleRing(s.buffer)
        self._structure = self._template
        self._sign_now = self._sign_known
        self._running = False
        self._ever_started = False
        self._restarts = 0
        self._samples = 0
        self._next_attempt = s.initial_samples
        self._attempts = 0  # batch-fit attempts since the last start
        self._scale_before = math.nan  # running squared error before the last divergence
        self._reason = "warming up"  # why not running (warming up or diverged)
        self._estimate = None
        # the recursion: theta (eqs. 23/33), information R and its floor R_0, P = R^-1
        self._theta = np.zeros(size)
        self._theta_list: list[float] = []
        self._info = np.eye(size)
        self._floor = np.zeros((size, size))
        self._cov = np.eye(size)
        self._valid_theta = self._theta.copy()
        self._valid_cov = self._cov.copy()
        # memories in samples: the recursion's (1 / (1 - lambda)) and the recent information's
        self._memory = 1.0 / (1.0 - s.forgetting) if s.forgetting < 1.0 else math.inf
        self._recent = np.eye(size)  # recent information Q, for the coverage test
        self._recent_decay = 1.0 - 1.0 / s.excitation_memory  # per moving sample
        self._recent_pending = 0  # moving samples since Q last decayed
        self._blocks = parameter_blocks(self._template)
        self._conditioning_floor = np.zeros(len(self._blocks))
        self._frozen = np.zeros(len(self._blocks), dtype=bool)  # blocks not updated
        self._free: BoolArray | None = None  # parameters not frozen (None: all)
        # running measures
        self._excitation = 0.0
        self._excitation_rate = 1.0 / s.excitation_memory
        self._share_left = self._share_right = 0.0  # shares of samples engaging each branch
        self._share_rate = 1.0 / min(max(self._memory, 100.0), 100_000.0)
        self._short = math.nan  # short running mean of squared one-step errors
        self._long = math.nan  # long running mean (the scale)
        self._since_start = 0  # informative samples since the (re)initialisation
        self._since_check = 0
        self._deadband = 0.0
        self._u_range = (0.0, 0.0)
        # carried signals: backlash (u(t-1), y(t-1)); cascade u(t-1), u(t-2), x lags, y lags
        self._u1 = 0.0
        self._u2 = 0.0
        self._y1 = 0.0
        self._x_lags: list[float] = []  # [x(t-2), x(t-3), .., x(t-max(na, 2))]
        self._x_resting = 0  # samples since x last changed, up to x(t-2)
        self._settling = 0  # samples the linear block takes to settle
        self._y_lags: list[float] = []  # [y(t-1), .., y(t-nb)]
        self._seed_pending = False  # seeded; waiting for the samples the first row needs
        self._seeded = False  # the recursion started from a seed (until a re-initialisation)

    def seed(self, estimate: Estimate) -> Estimate:
        """Continue from a saved ``estimate`` (e.g. a checkpoint's) instead of a batch fit.

        Forgets all samples, then starts the recursion from the estimate: ``theta`` from its
        parameters (eq. 34 inverted), the information ``R`` from its covariance and residual
        (``cov_theta = sigma^2 R^-1``, so that new rows weigh against it as they did before),
        the floor ``R_0`` and the coverage reference from that ``R``. The first samples only
        fill the signals a regressor row needs (two for a backlash; for a cascade until the
        internal ``x`` is determined, at most ``initial_samples``); meanwhile the estimate is
        the saved one. The state then follows the relative standard deviation as usual.

        Raises :class:`GenBacklashError` (the identifier unchanged) when the estimate cannot
        seed it: another structure, another branch sense than the one given, no valid model,
        or no finite covariance and residual.

        Parameters
        ----------
        estimate : Estimate
            The saved estimate.

        Returns
        -------
        Estimate
            The new current estimate: the saved parameters and covariance. The sample
            count goes on from the estimate's ``samples``.

        Examples
        --------
        >>> from genbacklash_core import Structure, paper_example
        >>> truth = paper_example(1).model
        >>> saved = Estimate(Structure(3), truth.parameters(), np.eye(8) * 1e-6, 0.02, 0.6,
        ...                  "converged", 0.9, 5000)
        >>> ident = RecursiveIdentifier(degree=3)
        >>> est = ident.seed(saved)
        >>> est.state.value, est.model == truth, ident.from_seed
        ('converged', True, True)
        >>> data = paper_example(1).generate(seed=1, n_samples=600)
        >>> after = ident.update_many(data.u, data.y)
        >>> after.state.value, bool(np.max(np.abs(after.parameters - truth.parameters())) < 0.02)
        ('converged', True)
        """
        prior = seed_prior(self._template, self._sign_known, estimate)
        self.reset()
        s = self.settings
        saved = estimate.structure
        structure = Structure(saved.degree, saved.na, saved.nb, saved.sign)
        info = prior.information
        cov = scaled_inverse(info)
        if cov is None:  # seed_prior checked that info is positive definite
            raise GenBacklashError("cannot seed: the estimate's information is singular")
        self._structure = structure
        self._sign_now = True
        self._theta = prior.theta.copy()
        self._info = info.copy()
        self._floor = info / s.covariance_bound  # R_0: P <= bound * P_seed
        self._cov = cov
        self._recent = info * min(1.0, s.excitation_memory / prior.rows)
        self._blocks = parameter_blocks(structure)
        self._set_frozen(np.zeros(len(self._blocks), dtype=bool))
        self._conditioning_floor = conditioning_floor(
            structure,
            block_conditioning(structure, info),
            s.min_conditioning,
            s.min_linear_conditioning,
        )
        self._valid_theta = self._theta.copy()
        self._valid_cov = self._cov.copy()
        self._short = self._long = prior.sigma2
        self._excitation = estimate.excitation
        n = structure.degree
        left, right = float(info[1, 1]), float(info[n + 2, n + 2])  # engaged rows per branch
        self._share_left, self._share_right = left / prior.rows, right / prior.rows
        if structure.cascade:
            self._settling = settling_samples(structure, prior.p)
        self._ever_started = True
        self._seeded = True
        self._seed_pending = True
        self._samples = estimate.samples
        self._next_attempt = self._samples + max(structure.na, structure.nb, 1) + 1
        self._reason = f"seeded from a saved estimate ({estimate.state.value})"
        return self.estimate

    @property
    def from_seed(self) -> bool:
        """True while the estimate rests mainly on a seed (:meth:`seed`): fewer informative
        samples than the recursion remembers (``1 / (1 - forgetting)``, at most ``buffer``)
        have updated it since, and it was not re-initialised."""
        memory = min(self._memory, float(self.settings.buffer))
        return self._seeded and self._since_start < memory

    def _start_seeded(self) -> None:
        """Start the recursion from the seed once the buffered samples give the first row's
        signals (for a cascade: once the internal ``x`` no longer depends on its start)."""
        s = self.settings
        structure = self._structure
        u, y = self._ring.window()
        if structure.cascade and u.size < s.initial_samples:
            p = structure.from_theta(self._theta)
            lo, hi = play_bounds(*structure.branches(p, u))
            if _merge_index(lo, hi, play_operator(lo, hi, -math.inf)) < 0:
                self._next_attempt = self._samples + 16
                return
        self._deadband = s.input_deadband * float(np.ptp(u))
        self._u_range = (float(u.min()), float(u.max()))
        self._carry_from_window(self._theta, u, y)
        self._seed_pending = False
        self._running = True
        self._reason = ""

    def update(self, u: float, y: float) -> Estimate:
        """Take one sample: one recursive least-squares step. Returns the current estimate."""
        uf, yf = as_sample(u, y)
        if not (abs(uf) <= self._u_limit and abs(yf) <= self._y_limit):  # NaN fails too
            if self.settings.nonfinite == "drop":
                return self.estimate
            raise NonFiniteInputError(
                f"sample {self._samples} is not finite (u={uf!r}, y={yf!r}) or beyond "
                f"|u| <= {self._u_limit:.3g}, |y| <= {self._y_limit:.3g}; pass "
                "nonfinite='drop' in the settings to skip such samples"
            )
        self._ring.push(uf, yf)
        self._samples += 1
        if self._running:
            if self._structure.cascade:
                self._step_cascade(uf, yf)
            else:
                self._step_backlash(uf, yf)
            self._after_samples(1)
        elif self._samples >= self._next_attempt:
            self._initialise()
        self._estimate = None
        return self.estimate

    def update_many(self, u: ArrayLike, y: ArrayLike) -> Estimate:
        """Take a series of samples, in blocks of ``settings.block`` (see the module notes)."""
        uu, yy = as_series(u, y)
        bad = ~((np.abs(uu) <= self._u_limit) & (np.abs(yy) <= self._y_limit))  # NaN too
        if bad.any():
            if self.settings.nonfinite == "drop":
                uu, yy = uu[~bad], yy[~bad]
            else:
                where = int(np.argmax(bad))
                raise NonFiniteInputError(
                    f"{int(bad.sum())} of {uu.size} samples are not finite or beyond |u| <= "
                    f"{self._u_limit:.3g}, |y| <= {self._y_limit:.3g} (first at index "
                    f"{where}); pass nonfinite='drop' in the settings to skip such samples"
                )
        start = 0
        block = self.settings.block
        while start < uu.size:
            if self._running:
                take = min(block, uu.size - start)
            else:  # buffer up to the next initialisation attempt
                take = min(uu.size - start, max(self._next_attempt - self._samples, 1))
            ub, yb = uu[start : start + take], yy[start : start + take]
            self._ring.extend(ub, yb)
            self._samples += take
            start += take
            if self._running:
                self._block(ub, yb)
                self._after_samples(take)
            elif self._samples >= self._next_attempt:
                self._initialise()
        self._estimate = None
        return self.estimate

    # ------------------------------------------------------------------ initialisation

    def _initialise(self) -> None:
        """Start (or restart) the recursion from a batch fit over buffered samples.

        The first start and the first attempt after a divergence use the whole buffer. A
        restart must also fit: its residual may not exceed ``divergence_ratio`` times the
        running one before the divergence (a buffer holding the burst that caused it would
        not), so later attempts use the latest ``initial_samples`` only, at growing
        intervals, until one fits; after a few rejections any converged fit is taken (the
        noise may really have grown).
        """
        if self._seed_pending:
            self._start_seeded()
            return
        s = self.settings
        attempt = self._attempts
        self._attempts += 1
        interval = max(s.initial_samples // 4, 1) * 2 ** min(attempt, 6)
        self._next_attempt = self._samples + min(interval, s.buffer)
        latest = self._ever_started and attempt > 0  # a retried restart: the latest only
        u, y = self._ring.window(s.initial_samples if latest else None)
        found = cold_fit(self._structure, self._sign_now, u, y)
        if isinstance(found, str):
            self._reason = f"batch fit failed: {found}"
            return
        structure, p = found
        deadband = s.input_deadband * float(np.ptp(u))
        fit = fit_window(
            structure,
            u,
            y,
            p,
            iterations=_INIT_ITERATIONS,
            tol=1e-6,
            settle=0.05,
            deadband=deadband,
        )
        if isinstance(fit, FitFailure):
            self._reason = f"batch fit failed: {fit.reason}"
            return
        cov = scaled_inverse(fit.information)
        if cov is None:
            self._reason = "batch fit failed: singular information matrix"
            return
        before = self._scale_before
        limit = s.divergence_ratio * s.divergence_ratio * before  # (** may overflow)
        if attempt < _MAX_REJECTIONS and math.isfinite(before) and fit.sigma2 > limit:
            self._reason = (
                f"batch fit rejected: residual {math.sqrt(fit.sigma2):.3g} against "
                f"{math.sqrt(before):.3g} before the divergence (the buffer may hold the fault)"
            )
            return
        self._structure = structure
        self._sign_now = True
        self._theta = fit.theta.copy()
        self._info = fit.information.copy()
        self._floor = fit.information / s.covariance_bound  # R_0: P <= bound * P_init
        rows = max(fit.rows.target.size, 1)
        self._recent = fit.information * min(1.0, s.excitation_memory / rows)
        self._recent_pending = 0
        self._blocks = parameter_blocks(structure)
        self._set_frozen(np.zeros(len(self._blocks), dtype=bool))
        self._conditioning_floor = conditioning_floor(
            structure,
            block_conditioning(structure, fit.information),
            s.min_conditioning,
            s.min_linear_conditioning,
        )
        self._cov = cov
        self._valid_theta = self._theta.copy()
        self._valid_cov = self._cov.copy()
        self._short = self._long = max(fit.sigma2, 1e-300)
        self._deadband = deadband
        self._u_range = (float(u.min()), float(u.max()))
        self._excitation = fit.excitation
        self._share_left, self._share_right = self._initial_shares(fit)
        self._since_start = 0
        self._since_check = 0
        self._carry_from_window(fit.theta, u, y)
        if self._ever_started:
            self._restarts += 1
        self._ever_started = True
        self._running = True
        self._attempts = 0
        self._reason = ""

    def _initial_shares(self, fit: WindowFit) -> tuple[float, float]:
        """Shares of the initial window's samples that engaged each branch."""
        phi = fit.rows.phi
        total = max(fit.rows.informative.size, 1)
        n = self._structure.degree
        left = float(np.count_nonzero(phi[:, 1] != 0.0)) / total  # the f1 column of eq. (22)
        right = float(np.count_nonzero(phi[:, n + 2] != 0.0)) / total  # the -f2 column
        return left, right

    def _carry_from_window(self, theta: FloatArray, u: FloatArray, y: FloatArray) -> None:
        """The signals the next regressor row needs, from the end of the initial window."""
        structure = self._structure
        self._u1 = float(u[-1])
        self._u2 = float(u[-2])
        self._y1 = float(y[-1])
        if not structure.cascade:
            return
        p = structure.from_theta(theta)
        lo, hi = play_bounds(*structure.branches(p, u))
        x = play_operator(lo, hi, -math.inf)  # eq. (36); determined after the first engagement
        lags = max(structure.na, 2) - 1
        self._x_lags = [float(v) for v in x[u.size - 1 - lags : u.size - 1][::-1]]
        self._x_resting = int(min(samples_since_change(x[: u.size - 1])[-1], 1e9))
        self._settling = settling_samples(structure, p)
        nb = structure.nb
        self._y_lags = [float(v) for v in y[u.size - nb :][::-1]] if nb else []

    # ------------------------------------------------------------------ one sample

    def _branches_at(self, u: float) -> tuple[float, float, float, float]:
        """``L(u), R(u), xi1, xi2`` from the separated vector (eqs. 11-12, 25-26)."""
        th = self._theta_list
        n = self._structure.degree
        xi1 = u + th[1] / th[0]  # eq. (25), c_L = theta_2 / theta_1 (eq. 34)
        xi2 = u - th[n + 2] / th[n + 1]  # eq. (26)
        left = th[n] if n > 1 else th[0]
        right = th[2 * n + 1] if n > 1 else th[n + 1]
        for i in range(n - 1, 1, -1):  # Horner on m_n .. m_2
            left = left * xi1 + th[i]
            right = right * xi2 + th[n + 1 + i]
        if n > 1:
            left = left * xi1 + th[0]
            right = right * xi2 + th[n + 1]
        return left * xi1, right * xi2, xi1, xi2

    def _row_backlash(self, u: float, f1: bool, f2: bool, xi1: float, xi2: float) -> list[float]:
        """One row of eq. (22)."""
        n = self._structure.degree
        row = [0.0] * self._structure.n_parameters
        if f1:
            row[0], row[1] = u, 1.0
            power = xi1
            for i in range(2, n + 1):
                power *= xi1
                row[i] = power
        if f2:
            row[n + 1], row[n + 2] = u, -1.0
            power = xi2
            for i in range(2, n + 1):
                power *= xi2
                row[n + 1 + i] = power
        return row

    def _keep(self, left: bool, right: bool, linear: bool) -> list[float]:
        """Logs of the information each block keeps for one row.

        A branch engaged in a share ``s`` of the moving samples forgets ``(1 - lambda) / s``
        per row, so that it remembers about ``1 / (1 - lambda)`` samples of time; the linear
        block forgets ``1 - lambda`` per moving sample.
        """
        rate = 1.0 - self.settings.forgetting

        def branch(share: float) -> float:
            return math.log1p(-min(rate / max(share, _MIN_SHARE), _MAX_FORGETTING))

        return [
            branch(self._share_left) if left else 0.0,
            branch(self._share_right) if right else 0.0,
            math.log1p(-rate) if linear and rate < 1.0 else 0.0,
        ]

    def _usable(self, left: bool, right: bool) -> bool:
        """False when the row belongs to a frozen block (a branch it engages, or linear)."""
        frozen = self._frozen
        if (left and frozen[0]) or (right and frozen[1]):
            return False
        return left or right or not self._linear_frozen

    @property
    def _linear_frozen(self) -> bool:
        """True when the cascade's linear block is frozen (there is one)."""
        return self._frozen.size > 2 and bool(self._frozen[2])

    def _set_frozen(self, frozen: BoolArray) -> None:
        """Freeze blocks: their rows are skipped, their parameters held (``_free``)."""
        self._frozen = frozen
        if not frozen.any():
            self._free = None
            return
        free = np.ones(self._theta.size, dtype=bool)
        for (_, block), held in zip(self._blocks, frozen.tolist(), strict=True):
            if held:
                free[block] = False
        self._free = free

    def _step_backlash(self, u: float, y: float) -> None:
        """One RLS step for a backlash alone (eqs. 22-24 with eqs. 25-28)."""
        s = self._structure.sign
        self._theta_list = self._theta.tolist()
        left, right, xi1, xi2 = self._branches_at(u)
        y1 = self._y1
        moving = abs(u - self._u1) > self._deadband
        f1 = moving and (left - y1) * s <= 0.0  # eq. (27) with the measured x(t-1)
        f2 = moving and (y1 - right) * s <= 0.0  # eq. (28)
        self._track_shares(moving, f1, f2, f1 or f2)
        if f1 or f2:
            row = self._row_backlash(u, f1, f2, xi1, xi2)
            use = self._usable(f1, f2)
            keep = self._keep(f1, f2, False) if use else [0.0, 0.0, 0.0]
            # target x(t): eq. (24), the hold term vanishes on engaged rows
            self._update(np.array([row]), np.array([y]), np.array([use]), keep, None)
        self._u1, self._y1 = u, y

    def _step_cascade(self, u: float, y: float) -> None:
        """One RLS step for the cascade (eqs. 32-37), internal x propagated by eq. (36)."""
        structure = self._structure
        s = structure.sign
        self._theta_list = self._theta.tolist()
        u1 = self._u1
        left, right, xi1, xi2 = self._branches_at(u1)
        x2 = self._x_lags[0]  # x(t-2)
        moving = abs(u1 - self._u2) > self._deadband
        f1 = (left - x2) * s <= 0.0  # f1(t-1), eq. (27)
        f2 = (x2 - right) * s <= 0.0  # f2(t-1), eq. (28)
        live = moving and (f1 or f2 or self._x_resting <= self._settling)
        self._track_shares(moving, f1 and moving, f2 and moving, live)
        if live:
            row = self._row_backlash(u1, f1, f2, xi1, xi2)
            row[structure.n_backlash :] = [
                *self._x_lags[: structure.na - 1],  # x(t-2) .. x(t-r), eq. (32)
                *(-v for v in self._y_lags),  # -y(t-1) .. -y(t-p)
            ]
            hold = x2 if not (f1 or f2) else 0.0  # x(t-2)[1-f1(t-1)][1-f2(t-1)]
            use = self._usable(f1, f2)
            linear = not self._linear_frozen
            keep = self._keep(f1, f2, linear) if use else [0.0, 0.0, 0.0]
            target = np.array([y - hold])  # eq. (35)
            self._update(np.array([row]), target, np.array([use]), keep, None)
        lo, hi = (right, left) if right <= left else (left, right)
        x1 = min(max(x2, lo), hi)  # x(t-1): one play-operator step, eq. (36)
        self._x_resting = 0 if x1 != x2 else self._x_resting + 1
        self._x_lags = [x1, *self._x_lags[:-1]]
        if self._y_lags:
            self._y_lags = [y, *self._y_lags[:-1]]
        self._u2, self._u1 = u1, u

    def _track_shares(self, moving: bool, left: bool, right: bool, informative: bool) -> None:
        """Running shares of moving samples engaging each branch; share of informative ones.

        The branch shares count moving samples only, so that a stretch without input
        motion is no time for the forgetting either.
        """
        if moving:
            a = self._share_rate
            self._share_left += (float(left) - self._share_left) * a
            self._share_right += (float(right) - self._share_right) * a
            self._recent_pending += 1
        self._excitation += (float(informative) - self._excitation) * self._excitation_rate

    # ------------------------------------------------------------------ the update

    def _scaling(self, keep: list[float]) -> FloatArray:
        """``d d^T`` for the block keeps (``d = exp(keep / 2)`` per parameter)."""
        n1 = self._structure.degree + 1
        d = np.array(
            [math.exp(0.5 * keep[0])] * n1
            + [math.exp(0.5 * keep[1])] * n1
            + [math.exp(0.5 * keep[2])] * (self._theta.size - 2 * n1)
        )
        return np.asarray(d[:, None] * d, dtype=np.float64)

    def _update(
        self,
        phi: FloatArray,
        target: FloatArray,
        use: BoolArray,
        keep: list[float],
        recent_weights: FloatArray | None,
    ) -> None:
        """``R <- D (R - R_0) D + R_0 + Phi^T Phi``, ``theta += R^-1 Phi^T e`` (module notes).

        ``keep`` holds the logs of the information each block keeps. The recent information
        of the coverage test takes every row (weighted by ``recent_weights`` within a block),
        after decaying by ``1 - 1/excitation_memory`` per moving sample since its last
        update; the recursion takes only the rows of unfrozen blocks.
        """
        gram = phi.T @ phi
        decay = self._recent_decay**self._recent_pending
        self._recent_pending = 0
        if recent_weights is None:
            self._recent = self._recent * decay + gram
        else:
            self._recent = self._recent * decay + (phi.T * recent_weights) @ phi
        if not use.all():
            phi, target = phi[use], target[use]
            if target.size == 0:
                return
            gram = phi.T @ phi
        errors = target - phi @ self._theta  # a priori one-step errors (eqs. 24/35)
        free = self._free
        if free is not None:  # frozen parameters gain no information and do not move
            phi = phi * free
            gram = phi.T @ phi
        info = (self._info - self._floor) * self._scaling(keep) + self._floor + gram
        try:
            cov = np.linalg.inv(info)  # info >= R_0 > 0: never singular in exact arithmetic
            if free is None:
                step = cov @ (phi.T @ errors)
            else:  # the free parameters given the frozen ones
                step = np.zeros_like(self._theta)
                step[free] = np.linalg.solve(info[np.ix_(free, free)], phi[:, free].T @ errors)
        except np.linalg.LinAlgError:
            self._diverge("the information matrix became singular")
            return
        if not math.isfinite(float(step.sum())):
            self._diverge("the estimate became non-finite")
            return
        self._info = info
        self._cov = np.asarray(cov, dtype=np.float64)
        self._theta = self._theta + step
        self._track_errors(errors * errors)

    def _block(self, u: FloatArray, y: FloatArray) -> None:
        """The update for a block of samples, regressors at the block-start estimate."""
        structure = self._structure
        p = structure.from_theta(self._theta)
        if structure.cascade:
            phi, target, rows, e1, e2, moving = self._rows_cascade(p, u, y)
        else:
            phi, target, rows, e1, e2, moving = self._rows_backlash(p, u, y)
        rate = self._share_rate
        # running shares, sample by sample: s(t) = s(t-1) + a (flag(t) - s(t-1))
        # the same over the moving samples only (the shares hold while the input rests)
        share_left = np.full(u.size, self._share_left)
        share_right = np.full(u.size, self._share_right)
        if moving.any():
            left = _ewma(e1[moving].astype(np.float64), rate, self._share_left)
            right = _ewma(e2[moving].astype(np.float64), rate, self._share_right)
            share_left[moving], share_right[moving] = left, right
            self._share_left, self._share_right = float(left[-1]), float(right[-1])
        excitation = _ewma(rows.astype(np.float64), self._excitation_rate, self._excitation)
        self._excitation = float(excitation[-1])
        moving_count = int(np.count_nonzero(moving))
        if target.size == 0:
            self._recent_pending += moving_count
            return
        e1_rows, e2_rows = e1[rows], e2[rows]
        linear = structure.cascade
        frozen = self._frozen
        use = ~((e1_rows & frozen[0]) | (e2_rows & frozen[1]))
        if linear and self._linear_frozen:
            use &= e1_rows | e2_rows
        rate = 1.0 - self.settings.forgetting

        def branch(flags: BoolArray, share: FloatArray) -> float:
            forget = np.minimum(rate / np.maximum(share[flags], _MIN_SHARE), _MAX_FORGETTING)
            return float(np.log1p(-forget).sum())

        keep = [
            branch(e1_rows & use, share_left[rows]),
            branch(e2_rows & use, share_right[rows]),
            int(np.count_nonzero(use)) * math.log1p(-rate)
            if linear and not self._linear_frozen and rate < 1.0
            else 0.0,
        ]
        # recent information: each row decays by one step per later moving sample
        after = moving_count - np.cumsum(moving)[rows]
        weights = self._recent_decay ** after.astype(np.float64)
        self._recent_pending += moving_count
        self._update(phi, target, use, keep, weights)

    def _rows_backlash(self, p: FloatArray, u: FloatArray, y: FloatArray) -> _BlockRows:
        """Rows of eq. (22) for a block; flags: used rows, left and right engaged."""
        u_prev = np.concatenate([[self._u1], u[:-1]])
        y_prev = np.concatenate([[self._y1], y[:-1]])
        f1, f2 = _switching(self._structure, p, u, y_prev)  # eqs. (27)-(28)
        moving = np.abs(u - u_prev) > self._deadband
        e1, e2 = (f1 > 0.0) & moving, (f2 > 0.0) & moving
        rows = e1 | e2
        phi = _backlash_columns(self._structure, p, u[rows], f1[rows], f2[rows])  # eq. (22)
        self._u1, self._y1 = float(u[-1]), float(y[-1])
        return phi, y[rows], rows, e1, e2, moving

    def _rows_cascade(self, p: FloatArray, u: FloatArray, y: FloatArray) -> _BlockRows:
        """Rows of eq. (32) for a block, internal x by eq. (36) from the carried state."""
        structure = self._structure
        na, nb, size = structure.na, structure.nb, u.size
        m = max(na, 2)
        u_lag1 = np.concatenate([[self._u1], u[:-1]])  # u(t-1) per row
        u_lag2 = np.concatenate([[self._u2], u_lag1[:-1]])  # u(t-2)
        lo, hi = play_bounds(*structure.branches(p, u_lag1))
        xs = play_operator(lo, hi, self._x_lags[0])  # x(t-1) per row, eq. (36)
        # chronological x: [x(T-m) .. x(T-2), x(T-1) .. x(T+B-2)]
        x_seq = np.concatenate([self._x_lags[::-1], xs])
        x2 = x_seq[m - 2 : m - 2 + size]  # x(t-2) per row
        f1, f2 = _switching(structure, p, u_lag1, x2)  # f(t-1), eqs. (27)-(28)
        moving = np.abs(u_lag1 - u_lag2) > self._deadband
        # samples since x last changed, up to x(t-2), continuing the carried count
        resting = np.empty(size)
        resting[0] = self._x_resting
        if size > 1:
            since = samples_since_change(np.concatenate([[x_seq[m - 2]], xs[:-1]]))[1:]
            resting[1:] = np.minimum(since, self._x_resting + np.arange(1, size))
        changed_last = xs[-1] != (xs[-2] if size > 1 else x_seq[m - 2])
        self._x_resting = 0 if changed_last else int(resting[-1]) + 1
        live = moving & (((f1 + f2) > 0.0) | (resting <= self._settling))
        phi = np.empty((int(np.count_nonzero(live)), structure.n_parameters), order="F")
        n_bl = structure.n_backlash
        phi[:, :n_bl] = _backlash_columns(structure, p, u_lag1[live], f1[live], f2[live])
        col = n_bl
        for i in range(2, na + 1):
            phi[:, col] = x_seq[m - i : m - i + size][live]  # x(t-i), eq. (32)
            col += 1
        y_seq = np.concatenate([self._y_lags[::-1], y])  # [y(T-nb) .. y(T-1), y(T) ..]
        for j in range(1, nb + 1):
            phi[:, col] = -y_seq[nb - j : nb - j + size][live]  # -y(t-j)
            col += 1
        target = (y - x2 * (1.0 - f1) * (1.0 - f2))[live]  # eq. (35)
        self._x_lags = x_seq[-(m - 1) :][::-1].tolist()
        self._y_lags = y_seq[-nb:][::-1].tolist() if nb else []
        self._u2 = float(u_lag1[-1])
        self._u1 = float(u[-1])
        return phi, target, live, (f1 > 0.0) & moving, (f2 > 0.0) & moving, moving

    # ------------------------------------------------------------------ guards and state

    def _track_errors(self, squared: FloatArray) -> None:
        """Running means of the squared one-step errors (short: divergence; long: scale)."""
        ratio = self.settings.divergence_ratio
        limit = ratio * ratio * self._long  # (not **: an OverflowError for a huge ratio)
        if squared.size == 1:
            value = float(squared[0])
            self._short += (value - self._short) / _SHORT_MEMORY
            self._long += (min(value, limit) - self._long) / _LONG_MEMORY
        else:
            self._short = float(_ewma(squared, 1.0 / _SHORT_MEMORY, self._short)[-1])
            clipped = np.minimum(squared, limit)
            self._long = float(_ewma(clipped, 1.0 / _LONG_MEMORY, self._long)[-1])
        self._since_start += squared.size

    def _after_samples(self, count: int) -> None:
        """Divergence guards after a sample or a block."""
        if not self._running:
            return
        theta = self._theta
        structure = self._structure
        n = structure.degree
        s = structure.sign
        if not (math.isfinite(float(theta.sum())) and math.isfinite(self._short)):
            self._diverge("the estimate became non-finite")
            return
        m_l1, m_r1 = float(theta[0]), float(theta[n + 1])
        if m_l1 * s <= 0.0 or m_r1 * s <= 0.0:
            self._diverge(
                f"a branch slope changed sign (m_left_1={m_l1:.3g}, m_right_1={m_r1:.3g})"
            )
            return
        if theta[1] / m_l1 <= 0.0 or theta[n + 2] / m_r1 <= 0.0:
            self._diverge("a dead-zone constant became negative")
            return
        ratio2 = self.settings.divergence_ratio * self.settings.divergence_ratio
        if self._since_start > 2 * _SHORT_MEMORY and self._short > ratio2 * self._long:
            self._diverge(
                f"the one-step error blew up (RMS {math.sqrt(self._short):.3g} against a "
                f"running {math.sqrt(self._long):.3g})"
            )
            return
        self._since_check += count
        if self._since_check >= self.settings.check_every:
            self._since_check = 0
            u_recent, _ = self._ring.window()
            u_range = (
                min(self._u_range[0], float(u_recent.min())),
                max(self._u_range[1], float(u_recent.max())),
            )
            problem = structure.problem(structure.from_theta(theta), u_range)
            if problem is not None:
                self._diverge(problem)
                return
            if structure.cascade:
                self._settling = settling_samples(structure, structure.from_theta(theta))
            conditioning = block_conditioning(structure, self._recent)
            self._set_frozen(conditioning < self._conditioning_floor)
            self._valid_theta = theta.copy()
            self._valid_cov = self._cov.copy()

    def _diverge(self, why: str) -> None:
        """Stop the recursion, report the last valid estimate, re-initialise from the buffer."""
        self._running = False
        self._seeded = False
        self._theta = self._valid_theta.copy()
        self._cov = self._valid_cov.copy()
        self._scale_before = self._long
        self._initialise()
        if not self._running:
            self._reason = f"diverged: {why}; re-initialisation pending ({self._reason})"

    def _build_estimate(self) -> Estimate:
        """The estimate and its state, from the current internals."""
        structure = self._structure
        excitation = min(max(self._excitation, 0.0), 1.0)
        if not self._ever_started:
            state = EstimatorState.WARMING_UP
            return Estimate.empty(structure, self._samples, excitation, state, self._reason)
        theta = self._theta.copy()
        theta_list = theta.tolist()
        cov_theta = self._long * self._cov  # sigma^2 P
        p_list = natural_from_theta(structure, theta_list)
        rel = relative_std_of(p_list, natural_variances(structure, theta_list, cov_theta))
        if not self._running and not self._seed_pending:
            state, reason = EstimatorState.DIVERGED, self._reason
        elif self._excitation < self.settings.min_excitation:
            state = EstimatorState.NO_EXCITATION
            reason = (
                "estimate frozen: the input carries no information (informative share "
                f"{self._excitation:.3f})"
            )
        elif self._frozen.any():
            state = EstimatorState.NO_EXCITATION
            frozen = self._frozen.tolist()
            names = ", ".join(n for (n, _), f in zip(self._blocks, frozen, strict=True) if f)
            reason = f"frozen: the recent input sweeps too little of the {names} to identify it"
        else:
            converged = rel <= self.settings.converged_std
            state = EstimatorState.CONVERGED if converged else EstimatorState.CONVERGING
            reason = f"recursive update; relative std {rel:.3g}"
            if self._seed_pending:
                reason = f"{self._reason}; relative std {rel:.3g}"
            if self._restarts:
                reason += f"; re-initialised {self._restarts} time(s)"
        return Estimate.trusted(
            structure,
            np.array(p_list),
            lambda: natural_covariance(structure, theta, cov_theta),
            math.sqrt(self._short),
            excitation,
            state,
            confidence_of(state, rel, self.settings.converged_std),
            self._samples,
            reason,
        )


def _ewma(values: FloatArray, alpha: float, start: float) -> FloatArray:
    """``m(t) = m(t-1) + alpha (v(t) - m(t-1))`` from ``m = start``, for every sample."""
    if values.size == 0:
        return np.array([start])
    decay = 1.0 - alpha
    out, _ = signal.lfilter([alpha], [1.0, -decay], values, zi=[decay * start])
    return np.asarray(out, dtype=np.float64)
