"""The paper's iteration with internal-variable estimation (eqs. 22-29, 31-37): repeated
least-squares steps from a start until the parameters settle, with limit cycles caught.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.structure import Structure

from .regression import (
    backlash_regression,
    cascade_regression,
    solve_damped,
    solve_least_squares,
    undetermined_branch,
)
from .results import CYCLE_LOOKBACK, IterationCallback


@dataclass
class IterationOutcome:
    """Working state of :func:`run_iteration` (internal, mutable)."""

    p: FloatArray
    last_valid: FloatArray
    valid: bool  # whether p itself is a valid model on the data's input range
    history: list[FloatArray]
    iterations: int
    converged: bool
    reason: str
    period: int = 1  # length of the limit cycle the iteration settled in (1: a fixed point)
    damped: int = 0  # iterations whose regression was singular and took a damped step


# Far-off iterates overflow float64: their non-finite parameters and regressors are caught by
# the validity check and the solver (a singular regression).
@np.errstate(over="ignore", invalid="ignore")
def run_iteration(
    structure: Structure,
    u: FloatArray,
    y: FloatArray,
    p_start: FloatArray,
    max_iterations: int,
    tol: float,
    callback: IterationCallback | None,
    breaks: BoolArray | None = None,
) -> IterationOutcome:
    """The paper's iteration, steps (a)-(c) of §3b / §4b, from ``p_start``.

    For a backlash alone a singular regression (a branch not engaged under the current
    switching estimate, or polynomial columns that collapse on held inputs) takes a damped
    step that keeps the undetermined directions where they were (:func:`solve_damped`);
    only when even that fails does the iteration stop. A cascade stops there.
    """
    regression = cascade_regression if structure.cascade else backlash_regression
    u_range = (float(u.min()), float(u.max()))
    p = p_start.copy()
    out = IterationOutcome(p, p.copy(), True, [p.copy()], 0, False, "")
    change = float("nan")
    for iteration in range(1, max_iterations + 1):
        out.iterations = iteration
        phi, target = regression(structure, p, u, y, breaks)  # step (b): internal variables
        theta = solve_least_squares(phi, target) if target.size >= phi.shape[1] else None
        damped = False  # whether eq. (29) left some parameters undetermined this step
        if theta is None and target.size > 0 and not structure.cascade:
            # (a cascade's singular regression means a structure that does not fit, e.g. a
            # dead time it lacks: GUIDE §2; it ends there with that reason)
            theta = solve_damped(phi, target, structure.theta(p))
            out.damped += 1
            damped = True
        if theta is None:  # step (a) impossible
            out.reason = (
                f"iteration {iteration}: the regression became singular (a branch is never "
                "engaged or regressors are collinear): the model structure may not fit the data, "
                "e.g. a delay or order the model lacks, or the data do not excite both branches"
            )
            return out
        try:
            p_new = structure.from_theta(theta)
        except GenBacklashError as err:
            out.reason = f"iteration {iteration}: {err}"
            return out
        change = float(np.max(np.abs(p_new - p)))
        # The switching patterns can flip back and forth between iterations: a limit cycle.
        # Revisiting one of the last few iterates within tol is as settled as it gets.
        recent = np.array(out.history[-CYCLE_LOOKBACK:])
        distances = np.max(np.abs(recent - p_new), axis=1)[::-1]  # [1 back, 2 back, ...]
        period = int(np.argmin(distances)) + 1
        settled = float(distances[period - 1])
        p = out.p = p_new
        out.history.append(p.copy())
        if callback is not None:
            callback(iteration, p.copy())
        problem = structure.problem(p, u_range)
        out.valid = problem is None
        if out.valid:
            out.last_valid = p.copy()
        if settled <= tol * max(1.0, float(np.max(np.abs(p)))):  # step (c)
            if damped:
                # A damped step carries what eq. (29) does not determine: an iterate whose
                # branch no row engages is its own fixed point without being an estimate.
                out.reason = (
                    f"iteration {iteration}: the iteration settled with "
                    f"{undetermined_branch(structure, phi)}: eq. (29) does not determine that "
                    "branch (its parameters were carried over, not estimated)"
                )
                return out
            if problem is None:
                out.converged = True
                out.period = period
                out.reason = (
                    f"converged: parameter change {change:.2g} after {iteration} iterations"
                )
                if period > 1:
                    out.reason += f" (a period-{period} cycle of switching patterns)"
            else:
                out.reason = f"the iteration settled on an invalid model: {problem}"
            return out
    out.reason = (
        f"no convergence in {max_iterations} iterations (last parameter change {change:.2g})"
    )
    if (problem := structure.problem(p, u_range)) is not None:
        out.reason += f"; {problem}"  # the last iterate's problem, for the reason only
    return out
