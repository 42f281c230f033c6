"""A trajectory run through the scenario's drivetrain into the online identifier
(:func:`check_commissioning`, :func:`verify`): when it converged and how well.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from genbacklash_core._typing import FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.errors import GenBacklashError
from genbacklash_core.estimate import EstimatorState
from genbacklash_core.identify import nrmse
from genbacklash_core.online.windowed import WindowedIdentifier, WindowedSettings
from genbacklash_core.samples import sample_breaks
from genbacklash_core.scenarios import (
    OPERATION_BACKLASH,
    OperationSettings,
    drive,
    operation_record,
)
from genbacklash_core.simulate import simulate_backlash

from .limits import as_finite, as_positive, as_whole
from .trajectory import Trajectory


class Verification(NamedTuple):
    """What :func:`verify` found."""

    converged_at: float | None
    """Seconds from the first command from which the estimate stayed converged to the end
    of the trajectory (None: not converged at the end)."""
    nrmse: float
    """Free-run NRMSE of the final estimate against the truth (``inf`` without one)."""


@dataclass(frozen=True)
class CommissioningCheck:
    """The identifier on a simulated run of a trajectory (:func:`check_commissioning`).

    Attributes
    ----------
    converged_at : float or None
        Seconds from the first command from which the state stayed ``converged`` to the
        end of the trajectory; None when it was not converged at the end.
    nrmse : float
        Free-run NRMSE of the final estimate against the noise-free truth on an independent
        record of the scenario's ``"operation"`` motion over the same travel (``inf``
        without an estimate).
    state : EstimatorState
        The identifier's state at the end.
    reason : str
        Its reason.
    model : GeneralBacklash or None
        The final estimate (in the model's units).
    rows : int
        Encoder readings that arrived.
    """

    converged_at: float | None
    nrmse: float
    state: EstimatorState
    reason: str
    model: GeneralBacklash | None
    rows: int

    @property
    def converged(self) -> bool:
        """Converged at the end of the trajectory."""
        return self.converged_at is not None


def _drivetrain(
    trajectory: Trajectory,
    u_commands: FloatArray,
    model: GeneralBacklash,
    seed: int,
    encoder_rate: float,
    counts_per_rev: int,
    loss: float,
) -> tuple[FloatArray, FloatArray, FloatArray, float]:
    """The scenario's drivetrain on the commands: ``(stamps_ns, u, y, period_ns)`` of the
    readings that arrived (see :func:`genbacklash_core.scenarios.operation_record`)."""
    defaults = OperationSettings()
    cmd_period = 1e9 / trajectory.command_rate
    _, t, u, _, y, received, _, _ = drive(
        np.random.default_rng([int(seed), 31]),
        u_commands,
        model,
        command_rate=trajectory.command_rate,
        encoder_rate=encoder_rate,
        command_jitter_ns=round(min(defaults.command_jitter * 1e9, 0.5 * cmd_period)),
        stamp_jitter_ns=defaults.stamp_jitter * 1e9,
        quantum=2.0 * math.pi / counts_per_rev if counts_per_rev else 0.0,
        loss=loss,
    )
    enc_period = 1e9 / encoder_rate
    return (
        np.asarray(t[received], dtype=np.float64),
        np.asarray(u[received], dtype=np.float64),
        np.asarray(y[received], dtype=np.float64),
        enc_period,
    )


def check_commissioning(
    trajectory: Trajectory,
    model: GeneralBacklash = OPERATION_BACKLASH,
    seed: int = 0,
    *,
    travel: tuple[float, float] | None = None,
    degree: int = 3,
    settings: WindowedSettings | None = None,
    encoder_rate: float = 1000.0,
    counts_per_rev: int = 4096,
    loss: float = 0.02,
) -> CommissioningCheck:
    """Run ``trajectory`` through a simulated drivetrain into the online identifier.

    The drivetrain of :mod:`genbacklash_core.scenarios`: the commands held (zero-order
    hold, up to 0.2 ms late), ``model``'s play operator, an encoder at ``encoder_rate``
    whose stamps jitter (50 us), quantised to ``counts_per_rev`` (of ``2 pi`` units) and
    losing each reading with probability ``loss``. The readings feed a
    :class:`~genbacklash_core.online.windowed.WindowedIdentifier` (``degree``, ``settings``;
    by default the node's: degree 3, ``WindowedSettings()``) in steps of one command
    period. The NRMSE is that of the final estimate simulated free-run against the
    noise-free truth on 20 s of the scenario's ``"operation"`` motion over the same travel
    (an independent record, seeded by ``seed``).

    Parameters
    ----------
    trajectory : Trajectory
    model : GeneralBacklash
        The true drivetrain (in ``travel``'s units).
    seed : int
        Seeds the jitter, the losses and the validation record.
    travel : (float, float), optional
        Map the trajectory's range linearly onto this travel before simulating (the model's
        units): a check of the motion's *shape* on a drivetrain whose travel is another
        one; the identifier sees one row per command change whatever the scale. Default:
        the trajectory's own units.
    degree : int
    settings : WindowedSettings, optional
    encoder_rate : float
    counts_per_rev : int
        0: no quantisation.
    loss : float
        In ``[0, 0.95]``.

    Returns
    -------
    CommissioningCheck

    Examples
    --------
    >>> from genbacklash_core.excite import MotionLimits, commissioning_trajectory
    >>> traj = commissioning_trajectory(MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0))
    >>> check = check_commissioning(traj, seed=1)
    >>> check.state.value, check.converged_at is not None, check.nrmse < 0.02
    ('converged', True, True)
    """
    if not isinstance(trajectory, Trajectory):
        raise GenBacklashError(f"trajectory must be a Trajectory, got {trajectory!r}")
    if not isinstance(model, GeneralBacklash):
        raise GenBacklashError(f"model must be a GeneralBacklash, got {model!r}")
    seed = as_whole("seed", seed, 0)
    encoder_rate = as_positive("encoder_rate", encoder_rate)
    if encoder_rate < trajectory.command_rate:
        raise GenBacklashError("encoder_rate must be at least the trajectory's command_rate")
    counts_per_rev = as_whole("counts_per_rev", counts_per_rev, 0)
    loss = as_finite("loss", loss)
    if not 0.0 <= loss <= 0.95:
        raise GenBacklashError(f"loss must lie in [0, 0.95], got {loss!r}")
    lim = trajectory.limits
    if travel is None:
        low, high = lim.low, lim.high
        u_commands = np.asarray(trajectory.u, dtype=np.float64)
    else:
        low, high = as_finite("travel[0]", travel[0]), as_finite("travel[1]", travel[1])
        if not low < high:
            raise GenBacklashError(f"travel must be (low, high) with low < high, got {travel}")
        scale = (high - low) / lim.span
        u_commands = np.clip(low + (trajectory.u - lim.low) * scale, low, high)
    if not model.branches_separated(low, high):
        raise GenBacklashError(
            f"the model's branches cross within [{low:g}, {high:g}]; it is no backlash there"
        )
    t_ns, u, y, period = _drivetrain(
        trajectory, u_commands, model, seed, encoder_rate, counts_per_rev, loss
    )
    breaks = sample_breaks(t_ns, period)
    ident = WindowedIdentifier(degree, settings=settings)
    step = max(1, round(encoder_rate / trajectory.command_rate))
    converged_at: float | None = None
    estimate = ident.estimate
    for first in range(0, u.size, step):
        part = slice(first, first + step)
        estimate = ident.update_many(u[part], y[part], breaks[part])
        if estimate.state is EstimatorState.CONVERGED:
            if converged_at is None:
                converged_at = float(t_ns[min(first + step, u.size) - 1]) * 1e-9
        else:
            converged_at = None
    found = estimate.model
    fitted = found if isinstance(found, GeneralBacklash) else None
    error = math.inf
    if fitted is not None:
        validation = operation_record(
            OperationSettings(
                duration=20.0,
                model=model,
                travel=(low, high),
                v_max=1.25 * (high - low),  # the scenario's 3 rad/s on 2.4 rad of travel
                a_max=12.5 * (high - low),  # and its 30 rad/s^2
                command_jitter=0.0,
                stamp_jitter=0.0,
                counts_per_rev=0,
                loss=0.0,
            ),
            seed=seed,
        )
        try:
            simulated = simulate_backlash(fitted, validation.u_all, float(validation.x_all[0]))
            error = nrmse(validation.x_all, simulated)
        except GenBacklashError:  # the estimate overflows on the validation input
            error = math.inf
    return CommissioningCheck(
        converged_at, error, estimate.state, estimate.reason, fitted, int(u.size)
    )


def verify(
    trajectory: Trajectory,
    model: GeneralBacklash = OPERATION_BACKLASH,
    seed: int = 0,
    *,
    travel: tuple[float, float] | None = None,
) -> Verification:
    """When the identifier converged on ``trajectory``, and how good its estimate is.

    :func:`check_commissioning` with its defaults (the node's identifier, the scenario's
    encoder), reduced to ``(converged_at, nrmse)``.

    Parameters
    ----------
    trajectory : Trajectory
    model : GeneralBacklash
        The true drivetrain.
    seed : int
    travel : (float, float), optional
        See :func:`check_commissioning`.

    Returns
    -------
    Verification
        ``(converged_at_s or None, nrmse)``.

    Examples
    --------
    >>> from genbacklash_core.scenarios import STRAIGHT_BACKLASH
    >>> from genbacklash_core.excite import MotionLimits, commissioning_trajectory
    >>> traj = commissioning_trajectory(MotionLimits(-1.2, 1.2, v_max=3.0, a_max=30.0))
    >>> converged_at, error = verify(traj, STRAIGHT_BACKLASH, seed=0)
    >>> bool(converged_at < traj.duration), bool(error < 0.02)
    (True, True)
    """
    found = check_commissioning(trajectory, model, seed, travel=travel)
    return Verification(found.converged_at, found.nrmse)
