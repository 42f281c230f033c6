"""The batch identification functions: :func:`identify_backlash`, :func:`identify_cascade`
and :func:`backlash_misfit`.
"""

from __future__ import annotations

from genbacklash_core._typing import ArrayLike, BoolArray, FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.data import (
    NonFinitePolicy,
    as_order,
    check_excitation,
    check_scale,
)
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.structure import Structure

from .fitting import prepare_inputs, run_identification, sign_option
from .results import MAX_ITERATIONS, TOL, IdentificationResult, IterationCallback


def identify_backlash(
    u: ArrayLike,
    x: ArrayLike,
    degree: int = 3,
    *,
    sign: float | None = None,
    start: GeneralBacklash | None = None,
    refine: bool = True,
    max_iterations: int = MAX_ITERATIONS,
    tol: float = TOL,
    nonfinite: NonFinitePolicy = "raise",
    callback: IterationCallback | None = None,
    breaks: ArrayLike | None = None,
    restart_holds: bool = False,
) -> IdentificationResult:
    """Identify a general backlash from input ``u`` and measured output ``x`` (eqs. 22-29).

    Parameters
    ----------
    u, x : array_like, shape (N,)
        Actuator command and measured (load-side) position.
    degree : int
        Polynomial degree ``n >= 1`` of each branch; 1 is the ideal backlash.
    sign : {+1, -1, None}
        Whether the branches increase or decrease; None detects it from the data.
    start : GeneralBacklash, optional
        Initial estimate; default the paper's ``m_1 = sign``, ``c = 0.001``.
    refine : bool
        Run the output-error refinement after the iteration (default True).
    max_iterations, tol : int, float
        The iteration stops when no parameter moves more than ``tol * max(1, max|p|)``.
    nonfinite : {"raise", "drop"}
        Policy for NaN/inf samples.
    callback : callable, optional
        Called as ``callback(iteration, parameters)`` after each iteration.
    breaks : array_like of bool, shape (N,), optional
        The sample rule (:func:`~genbacklash_core.samples.sample_breaks`): True where a
        sample does not follow the one before on the encoder's clock (a lost reading, a
        gap). Rows of eq. (24) are never formed across a break. Default: all consecutive.
    restart_holds : bool
        The refinement restarts its simulation at held readings the play operator does not
        describe (:func:`described_breaks`: a load that moves on inside the play), judged
        again at each refined estimate. ``genbacklash identify`` sets it. Off by default:
        on a smooth input lagged 5 samples (a servo the model lacks) it read the play worse.

    Returns
    -------
    IdentificationResult

    Raises
    ------
    NonFiniteInputError, NotEnoughExcitationError, GenBacklashError

    Examples
    --------
    >>> import numpy as np
    >>> from genbacklash_core import paper_example
    >>> ex = paper_example(1)
    >>> data = ex.generate(seed=0)
    >>> result = identify_backlash(data.u, data.y, degree=3)
    >>> result.converged
    True
    >>> bool(np.max(np.abs(result.model.parameters() - ex.model.parameters())) < 0.03)
    True
    """
    structure, uu, xx, bb, p0 = backlash_problem(u, x, degree, sign, start, nonfinite, breaks)
    return run_identification(
        structure,
        uu,
        xx,
        start=p0,
        max_iterations=max_iterations,
        tol=tol,
        refine=refine,
        callback=callback,
        breaks=bb,
        restart_holds=restart_holds,
    )


def backlash_misfit(
    u: ArrayLike, x: ArrayLike, degree: int = 1, *, breaks: ArrayLike | None = None
) -> float:
    """The free-run NRMSE of the backlash the paper's iteration finds (no refinement).

    The number ``identify_backlash(u, x, degree, refine=False, breaks=breaks).fit.nrmse``
    reads, to the bit, at less cost: without the refinement a candidate's ``converged``
    never chooses between starts (the restarts follow the iteration's own convergence and
    the lower misfit), so the check that the data reach every branch of a settled candidate
    (a free run of its own, which decides ``converged`` alone) is skipped. What
    :func:`~genbacklash_core.servo.estimate_servo` scores each candidate servo by.

    Raises
    ------
    GenBacklashError
        As :func:`identify_backlash` (too few samples, no excitation, bad input).

    >>> from genbacklash_core import paper_example
    >>> data = paper_example(1).generate(seed=0)
    >>> misfit = backlash_misfit(data.u, data.y, 3)
    >>> misfit == identify_backlash(data.u, data.y, 3, refine=False).fit.nrmse
    True
    """
    structure, uu, xx, bb, _ = backlash_problem(u, x, degree, None, None, "raise", breaks)
    result = run_identification(
        structure,
        uu,
        xx,
        start=None,
        max_iterations=MAX_ITERATIONS,
        tol=TOL,
        refine=False,
        callback=None,
        breaks=bb,
        support=False,
    )
    return result.fit.nrmse


def backlash_problem(
    u: ArrayLike,
    x: ArrayLike,
    degree: int,
    sign: float | None,
    start: GeneralBacklash | None,
    nonfinite: NonFinitePolicy,
    breaks: ArrayLike | None,
) -> tuple[Structure, FloatArray, FloatArray, BoolArray | None, FloatArray | None]:
    """:func:`identify_backlash`'s input checked: the structure (its sign detected unless
    given), the prepared samples and breaks, the start's parameters (None: the paper's)."""
    degree = as_order("degree", degree)
    if degree < 1:
        raise GenBacklashError(f"degree must be >= 1, got {degree}")
    uu, xx, bb = prepare_inputs(u, x, nonfinite, breaks)
    structure = Structure(degree, 0, 0, 1.0)
    check_excitation(uu, xx, structure.n_parameters)
    check_scale(uu, xx, degree)
    if start is not None and not isinstance(start, GeneralBacklash):
        raise GenBacklashError(f"start must be a GeneralBacklash or None, got {start!r}")
    s = start.sign if start is not None else sign_option(sign, uu, xx, 0)
    structure = Structure(degree, 0, 0, s)
    p0 = None
    if start is not None:
        if start.degree != degree:
            raise GenBacklashError(f"start has degree {start.degree}, expected {degree}")
        p0 = start.parameters()
    return structure, uu, xx, bb, p0


def identify_cascade(
    u: ArrayLike,
    y: ArrayLike,
    degree: int = 3,
    na: int = 2,
    nb: int = 2,
    *,
    sign: float | None = None,
    start: Cascade | None = None,
    refine: bool = True,
    max_iterations: int = MAX_ITERATIONS,
    tol: float = TOL,
    nonfinite: NonFinitePolicy = "raise",
    callback: IterationCallback | None = None,
    breaks: ArrayLike | None = None,
) -> IdentificationResult:
    """Identify a general backlash followed by linear dynamics (eqs. 31-37).

    Parameters
    ----------
    u, y : array_like, shape (N,)
        Input of the backlash and output of the linear block.
    degree : int
        Polynomial degree of each branch.
    na, nb : int
        ``r >= 1`` input terms (``a_1 = 1`` included) and ``p >= 0`` output terms of eq. (30).
    sign, start, refine, max_iterations, tol, nonfinite, callback, breaks
        As in :func:`identify_backlash`; the linear block starts at zero. Rows whose
        measured lags reach across a break are left out.

    Examples
    --------
    >>> import numpy as np
    >>> from genbacklash_core import paper_example
    >>> ex = paper_example(3)
    >>> data = ex.generate(seed=0)
    >>> result = identify_cascade(data.u, data.y, degree=3, na=2, nb=2)
    >>> result.converged, result.model.linear.na
    (True, 2)
    >>> bool(np.max(np.abs(result.model.parameters() - ex.model.parameters())) < 0.03)
    True
    """
    degree, na, nb = as_order("degree", degree), as_order("na", na), as_order("nb", nb)
    if degree < 1:
        raise GenBacklashError(f"degree must be >= 1, got {degree}")
    if na < 1 or nb < 0:
        raise GenBacklashError(f"need na >= 1 and nb >= 0, got na={na}, nb={nb}")
    uu, yy, bb = prepare_inputs(u, y, nonfinite, breaks)
    structure = Structure(degree, na, nb, 1.0)
    check_excitation(uu, yy, structure.n_parameters)
    check_scale(uu, yy, degree)
    if start is not None and not isinstance(start, Cascade):
        raise GenBacklashError(f"start must be a Cascade or None, got {start!r}")
    s = start.backlash.sign if start is not None else sign_option(sign, uu, yy, na + 3)
    structure = Structure(degree, na, nb, s)
    p0 = None
    if start is not None:
        if Structure.of(start) != structure:
            raise GenBacklashError(
                f"start has structure {Structure.of(start)}, expected {structure}"
            )
        p0 = start.parameters()
    return run_identification(
        structure,
        uu,
        yy,
        start=p0,
        max_iterations=max_iterations,
        tol=tol,
        refine=refine,
        callback=callback,
        breaks=bb,
    )
