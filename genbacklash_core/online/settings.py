"""The settings of the two online identifiers: frozen dataclasses, validated on construction.

:class:`WindowedSettings` configures
:class:`~genbacklash_core.online.windowed.WindowedIdentifier` (a sliding window of warm-started
batch iterations), :class:`RecursiveSettings` configures
:class:`~genbacklash_core.online.recursive.RecursiveIdentifier` (one iteration per block over a
binned memory of rows). The settings they share (``bins``, ``idle_samples``,
``confidence_half_life``, ``input_deadband``, ``converged_std``, ``nonfinite``) mean the same
in both and are validated the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from genbacklash_core.data import NonFinitePolicy
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.estimate import check_setting

__all__ = ["RecursiveSettings", "WindowedSettings"]


@dataclass(frozen=True)
class WindowedSettings:
    """Settings of :class:`~genbacklash_core.online.windowed.WindowedIdentifier` (validated).

    Attributes
    ----------
    window : int
        ``W``, how much the fits remember (>= 20). For a backlash alone: regression rows
        (pairs of consecutive readings whose input moved), filed by branch and input region
        (:class:`~genbacklash_core.online.memory.RowMemory`): old rows are forgotten only where
        new ones cover the same region, and dwells, held commands and lost readings add
        nothing. For the cascade: the most recent ``W`` samples, where a dwell counts only
        up to twice the linear block's settling horizon (its later samples repeat a steady
        state: a joint at rest does not push the moves out). Larger: more accurate
        (std ~ 1/sqrt(W)); smaller: tracks drift with less lag (~ W/2 rows).
    bins : int
        Input regions per branch of the row memory (backlash alone).
    idle_samples : int
        Samples without a new informative row after which the estimate is reported as held
        (state ``no_excitation``, the estimate unchanged).
    confidence_half_life : float
        Samples over which the confidence of a held estimate halves (600000: ten minutes at
        1 kHz): an estimate no new data confirm is trusted less and less, never dropped.
    refit_every : int
        Smallest number of new samples between two fits (>= 1).
    refit_fraction : float
        ``K = max(refit_every, ceil(refit_fraction * len(window)))``: fits get rarer as the
        window grows, which bounds the amortised cost per sample. 0 refits every
        ``refit_every`` samples whatever the window length.
    iterations : int
        Warm-started iterations of the paper's method per fit (>= 1).
    tol, settle : float
        The iteration has settled when no parameter moves more than ``tol * max(1, max|p|)``
        or more than ``settle`` times its standard deviation; it stops there.
    refine : bool
        Follow each fit by output-error refinement (Levenberg-Marquardt) on the window: the
        maximum-likelihood estimate, free of the equation error's noise bias, at extra cost.
    refine_iterations : int
        Levenberg-Marquardt steps per fit, warm-started from the previous refined estimate.
    min_samples : int or None
        Samples before the first (cold) fit; default ``max(40, 6 * n_parameters)``.
    min_excitation : float
        A fit runs only when at least this share of the new samples since the last fit was
        informative (a branch engaged while the input moved); otherwise the estimate is
        frozen and the state is ``no_excitation``.
    min_conditioning : float
        A fit is accepted only when the latest ``excitation_window`` samples excite every
        block of parameters (left branch, right branch, linear block): the smallest
        eigenvalue of the block's normalised information matrix over those samples must
        reach this fraction of the best seen so far. An input that sweeps only a narrow part
        of a branch fails this, and fitting it would bend the whole polynomial to that part;
        the estimate is then frozen (``no_excitation``).
    min_linear_conditioning : float
        The same for the linear block of a cascade. Higher, because a slow input makes
        ``x`` and ``y`` nearly collinear and the noisy ``y`` in the regressors then biases
        the equation error strongly; random input keeps it above ~0.8 of its reference.
    excitation_window : int
        Samples of the coverage test above (>= 20).
    input_deadband : float
        The input counts as moving when a step exceeds this fraction of the widest input
        span fitted so far.
    converged_std : float
        ``converged`` needs every parameter's standard deviation below
        ``converged_std * max(1, max|p|)``; also the confidence scale.
    max_failures : int
        Consecutive fits that leave the valid set (crossing branches, flipped slope, unstable
        linear block) before the state is ``diverged`` and a cold restart is tried.
    nonfinite : {"raise", "drop"}
        NaN/inf samples, and samples too large for the regression (beyond
        :func:`~genbacklash_core.data.scale_limits`, ~1e30 for a cubic), raise
        :class:`~genbacklash_core.errors.NonFiniteInputError`, or are skipped.

    Notes
    -----
    The window trades accuracy for tracking. Measured on the paper's Example 1 (random
    input, SNR 25), all from a cold start:

    * default (``W = 1500``): max parameter error ~0.01-0.02 at 300 samples; a gap growing
      linearly is tracked ~800 samples behind;
    * ``window=2000``: tracking lag ~1100 samples;
    * ``window=5000, refine=True, iterations=1``: after 5000 samples as accurate as the
      batch fit (with refinement) on all of them; tracking lag ~2800 samples.

    The coverage test (``min_conditioning``) freezes the estimate while the latest
    ``excitation_window`` samples sweep too little of a branch; an input that scans the
    range more slowly than that is not trusted: raise ``excitation_window`` for it.

    Examples
    --------
    >>> WindowedSettings(window=5000, refine=True).window
    5000
    >>> WindowedSettings(window=5)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: window must lie in [20, inf], got 5
    """

    window: int = 1500
    bins: int = 16
    idle_samples: int = 1000
    confidence_half_life: float = 600_000.0
    refit_every: int = 25
    refit_fraction: float = 0.15
    iterations: int = 3
    tol: float = 1e-4
    settle: float = 0.2
    refine: bool = False
    refine_iterations: int = 2
    min_samples: int | None = None
    min_excitation: float = 0.05
    min_conditioning: float = 0.03
    min_linear_conditioning: float = 0.3
    excitation_window: int = 500
    input_deadband: float = 1e-4
    converged_std: float = 0.02
    max_failures: int = 3
    nonfinite: NonFinitePolicy = "raise"

    def __post_init__(self) -> None:
        check_setting("window", self.window, 20, math.inf, whole=True)
        check_setting("bins", self.bins, 1, 1000, whole=True)
        check_setting("idle_samples", self.idle_samples, 1, math.inf, whole=True)
        check_setting("confidence_half_life", self.confidence_half_life, 1.0, math.inf, whole=False)
        check_setting("refit_every", self.refit_every, 1, self.window, whole=True)
        check_setting("refit_fraction", self.refit_fraction, 0.0, 1.0, whole=False)
        check_setting("iterations", self.iterations, 1, 1000, whole=True)
        check_setting("tol", self.tol, 0.0, 1.0, whole=False)
        check_setting("settle", self.settle, 0.0, 100.0, whole=False)
        if not isinstance(self.refine, bool):
            raise GenBacklashError(f"refine must be True or False, got {self.refine!r}")
        check_setting("refine_iterations", self.refine_iterations, 1, 1000, whole=True)
        if self.min_samples is not None:
            check_setting("min_samples", self.min_samples, 20, self.window, whole=True)
        check_setting("min_excitation", self.min_excitation, 0.0, 1.0, whole=False)
        check_setting("min_conditioning", self.min_conditioning, 0.0, 1.0, whole=False)
        check_setting(
            "min_linear_conditioning", self.min_linear_conditioning, 0.0, 1.0, whole=False
        )
        check_setting("excitation_window", self.excitation_window, 20, math.inf, whole=True)
        check_setting("input_deadband", self.input_deadband, 0.0, 1.0, whole=False)
        check_setting("converged_std", self.converged_std, 1e-12, math.inf, whole=False)
        check_setting("max_failures", self.max_failures, 1, 1_000_000, whole=True)
        if self.nonfinite not in ("raise", "drop"):
            raise GenBacklashError(f"nonfinite must be 'raise' or 'drop', got {self.nonfinite!r}")


_MAX_MEMORY = 1 << 16  # rows per branch when nothing is forgotten (forgetting = 1)


@dataclass(frozen=True)
class RecursiveSettings:
    """Settings of :class:`~genbacklash_core.online.recursive.RecursiveIdentifier` (validated).

    Attributes
    ----------
    forgetting : float
        ``lambda`` in ``[0.5, 1]``: each branch remembers its newest ``M = 1 / (1 - lambda)``
        rows (moves between consecutive readings; ``M = 65536`` for 1), and each of its input
        regions at least ``ceil(M / (2 bins))`` however old. A drifting parameter is tracked
        about ``M / 2`` rows of its branch behind (on the paper's random input, one row per
        sample: ~``M`` samples); larger ``M`` is more accurate (std ~ ``1/sqrt(M)``) and
        costs more per iteration. Rows, not samples: a dwell or a held command adds none.
    bins : int
        Input regions per branch of the memory (1 to 1000).
    initial_samples : int
        Samples before the first batch fit (>= 20); the cascade's first fit takes its
        recent ``buffer`` samples, a backlash alone every informative row seen.
    buffer : int
        Recent samples kept for the cascade's batch fits (>= ``initial_samples``).
    block : int
        Samples between two iterations over the memory (1 to 4096); blocks without new
        rows cost nothing.
    covariance_bound : float
        The pull towards the current estimate is ``R_init / covariance_bound`` (``R_init``
        the information at the (re)initialisation), so the covariance never exceeds this
        multiple of its value then.
    input_deadband : float
        A row is informative only when the input step exceeds this fraction of the input
        span seen so far (a repeated command never counts).
    excitation_memory : int
        Memory, in samples, of the informative share reported as ``excitation``.
    min_excitation : float
        Kept for compatibility; no effect (the state follows ``idle_samples``).
    idle_samples : int
        Samples without a new informative row after which the state is ``no_excitation``
        (the estimate held).
    confidence_half_life : float
        Samples over which the confidence halves while no new row confirms a branch
        (600000: ten minutes at 1 kHz); the age is that of the branch whose newest row is
        oldest.
    min_conditioning, min_linear_conditioning : float
        Kept for compatibility; no effect: the binned memory keeps every region a branch
        was seen in, so a narrow sweep no longer bends the polynomial.
    divergence_ratio : float
        The one-step error has blown up when its short-term RMS exceeds this multiple of
        its long-term value.
    check_every : int
        Samples between updates of the cascade's settling horizon (the linear block's
        memory of a change of ``x``).
    converged_std : float
        ``converged`` needs every parameter's standard deviation below
        ``converged_std * max(1, max|p|)``; also the confidence scale.
    nonfinite : {"raise", "drop"}
        NaN/inf samples, and samples too large for the regression (beyond
        :func:`~genbacklash_core.data.scale_limits`), raise, or are skipped (a skipped
        sample breaks the chain of consecutive samples).

    Notes
    -----
    Measured with the defaults. Simulated drivetrain operation
    (:func:`~genbacklash_core.scenarios.operation_record`: moves, dwells, jogs, 100 Hz
    commands read at 1 kHz, quantised, 2 % of the readings lost), seeds 0-4: first estimate
    after 1.4-3.9 s, free-run NRMSE ~1e-4 after 60 s; gaps widening by 50 % over ten minutes
    tracked ~8 s behind; two minutes of one-way motion move no parameter by more than 1e-4.
    The paper's Example 1 (random input, SNR 25): a linearly growing gap is tracked ~500
    samples behind; up to 30 % of the readings lost at random leave the final error as it
    is without loss. ``update_many`` costs 2-5 us per sample, ``update`` ~10 us.

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
    bins: int = 16
    initial_samples: int = 300
    buffer: int = 1000
    block: int = 64
    covariance_bound: float = 20.0
    input_deadband: float = 1e-4
    excitation_memory: int = 200
    min_excitation: float = 0.02
    idle_samples: int = 1000
    confidence_half_life: float = 600_000.0
    min_conditioning: float = 0.03
    min_linear_conditioning: float = 0.3
    divergence_ratio: float = 5.0
    check_every: int = 100
    converged_std: float = 0.02
    nonfinite: NonFinitePolicy = "raise"

    def __post_init__(self) -> None:
        check_setting("forgetting", self.forgetting, 0.5, 1.0, whole=False)
        check_setting("bins", self.bins, 1, 1000, whole=True)
        check_setting("initial_samples", self.initial_samples, 20, 10_000_000, whole=True)
        check_setting("buffer", self.buffer, self.initial_samples, 100_000_000, whole=True)
        check_setting("block", self.block, 1, 4096, whole=True)
        check_setting("covariance_bound", self.covariance_bound, 1.0, math.inf, whole=False)
        check_setting("input_deadband", self.input_deadband, 0.0, 1.0, whole=False)
        check_setting("excitation_memory", self.excitation_memory, 1, 10_000_000, whole=True)
        check_setting("min_excitation", self.min_excitation, 0.0, 1.0, whole=False)
        check_setting("idle_samples", self.idle_samples, 1, 10_000_000_000, whole=True)
        check_setting("confidence_half_life", self.confidence_half_life, 1.0, math.inf, whole=False)
        check_setting("min_conditioning", self.min_conditioning, 0.0, 1.0, whole=False)
        check_setting(
            "min_linear_conditioning", self.min_linear_conditioning, 0.0, 1.0, whole=False
        )
        check_setting("divergence_ratio", self.divergence_ratio, 1.0, math.inf, whole=False)
        check_setting("check_every", self.check_every, 1, 10_000_000, whole=True)
        check_setting("converged_std", self.converged_std, 1e-12, math.inf, whole=False)
        if self.nonfinite not in ("raise", "drop"):
            raise GenBacklashError(f"nonfinite must be 'raise' or 'drop', got {self.nonfinite!r}")

    @property
    def branch_memory(self) -> int:
        """``M``: rows (moves) each branch remembers, ``1 / (1 - forgetting)``.

        >>> RecursiveSettings().branch_memory, RecursiveSettings(forgetting=1.0).branch_memory
        (500, 65536)
        """
        if self.forgetting >= 1.0:
            return _MAX_MEMORY
        return min(max(round(1.0 / (1.0 - self.forgetting)), 2), _MAX_MEMORY)

    @property
    def region_floor(self) -> int:
        """Rows each input region of a branch keeps however old: ``ceil(M / (2 bins))``.

        >>> RecursiveSettings().region_floor
        16
        """
        return max(math.ceil(self.branch_memory / (2 * self.bins)), 1)
