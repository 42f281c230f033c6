"""The drivetrain driven by the commands: the play operator on the held command at each
reading's instant, with wear and the hidden effects (:func:`drive`), into whole records
(:func:`operation_record`, :func:`arm_records`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.errors import GenBacklashError

from .clocks import readings, timeline
from .motions import operation_commands
from .record import OperationRecord
from .settings import HiddenEffects, OperationSettings
from .wear import simulate_worn

_BLOCK = 250  # samples per wear step of the simulation (0.25 s at 1 kHz)


def drive(
    rng: np.random.Generator,
    values: FloatArray,
    model: GeneralBacklash,
    *,
    command_rate: float,
    encoder_rate: float,
    command_jitter_ns: int,
    stamp_jitter_ns: float,
    wear: float = 0.0,
    noise: float = 0.0,
    quantum: float = 0.0,
    loss: float = 0.0,
    hidden: HiddenEffects | None = None,
) -> tuple[
    IntArray, IntArray, FloatArray, FloatArray, FloatArray, BoolArray, FloatArray, FloatArray
]:
    """The drivetrain's time line for commands ``values`` at the nominal command ticks (see
    the module notes): ``(command stamps, reading stamps, held input, load, reading,
    received, c_left, c_right)``, every reading included. Draws from ``rng`` in this order:
    command jitter, stamp jitter, noise, loss (each only when non-zero, loss always;
    :func:`timeline`, then :func:`readings`).
    ``hidden`` adds effects beyond the backlash (:class:`HiddenEffects`; it draws nothing):
    the held input stays the command, the load is the output before noise."""
    cmd_t, t = timeline(
        rng,
        values.size,
        command_rate=command_rate,
        encoder_rate=encoder_rate,
        command_jitter_ns=command_jitter_ns,
        stamp_jitter_ns=stamp_jitter_ns,
    )
    n = t.size
    k = np.searchsorted(cmd_t, t, side="right") - 1
    u = values[np.maximum(k, 0)]
    # the drivetrain, with linear wear of the dead zones, in blocks
    factor = 1.0 + wear * (np.arange(n) / max(n - 1, 1))
    block_factor = np.repeat(
        [float(np.mean(factor[s : min(s + _BLOCK, n)])) for s in range(0, n, _BLOCK)], _BLOCK
    )[:n]
    c_left, c_right = model.c_left * block_factor, model.c_right * block_factor
    v = u if hidden is None else hidden.motor(cmd_t, values, t)
    x0 = 0.5 * float(model.left(v[:1])[0] + model.right(v[:1])[0])  # at rest, mid-gap
    x = simulate_worn(model, v, x0, c_left, c_right)
    if hidden is not None:
        x = hidden.load(x, t)
    y, received = readings(rng, x, noise=noise, quantum=quantum, loss=loss)
    return cmd_t, t, u, x, y, received, c_left, c_right


def operation_record(
    settings: OperationSettings | None = None, seed: int = 0, *, hidden: HiddenEffects | None = None
) -> OperationRecord:
    """Simulate a drivetrain in operation (see the module notes).

    Parameters
    ----------
    settings : OperationSettings, optional
        Default: 60 s of ``"operation"`` with :data:`OPERATION_BACKLASH`.
    seed : int
        Seeds everything random (motions, jitter, loss, noise).
    hidden : HiddenEffects, optional
        Effects of the drivetrain beyond its backlash (a servo lag, a dead time, a load lag,
        an encoder offset, an output limit, a periodic error); none by default. They draw
        nothing from the random stream: the same seed gives the same motion, stamps, noise
        and losses with and without them.
    """
    cfg = OperationSettings() if settings is None else settings
    if not isinstance(cfg, OperationSettings):
        raise GenBacklashError(f"settings must be OperationSettings, got {cfg!r}")
    rng = np.random.default_rng([int(seed), 12])
    values, phase_starts = operation_commands(rng, cfg)
    return _driven_record(rng, cfg, seed, values, phase_starts, hidden)


def _driven_record(
    clock: np.random.Generator,
    cfg: OperationSettings,
    seed: int,
    values: FloatArray,
    phase_starts: tuple[tuple[str, float], ...],
    hidden: HiddenEffects | None = None,
) -> OperationRecord:
    """``cfg.model`` driven by the commands ``values`` (:func:`drive`, drawing the clocks,
    noise and losses from ``clock``), as an :class:`OperationRecord`."""
    cmd_t, t, u, x, y, received, c_left, c_right = drive(
        clock,
        values,
        cfg.model,
        command_rate=cfg.command_rate,
        encoder_rate=cfg.encoder_rate,
        command_jitter_ns=round(cfg.command_jitter * 1e9),
        stamp_jitter_ns=cfg.stamp_jitter * 1e9,
        wear=cfg.wear,
        noise=cfg.noise,
        quantum=cfg.quantum,
        loss=cfg.loss,
        hidden=hidden,
    )
    return OperationRecord(
        settings=cfg,
        seed=int(seed),
        command_t_ns=cmd_t,
        command_u=values,
        sample_t_ns=t,
        u_all=u,
        x_all=x,
        y_all=np.asarray(y, dtype=np.float64),
        received=received,
        c_left=c_left,
        c_right=c_right,
        phase_starts=phase_starts,
        hidden=hidden,
    )


def arm_records(
    models: tuple[GeneralBacklash, ...] | list[GeneralBacklash],
    settings: OperationSettings | None = None,
    seed: int = 0,
) -> list[OperationRecord]:
    """An arm of several drivetrains on one clock: one :class:`OperationRecord` per model.

    Each joint moves on its own (its commands drawn from its own stream, seeded by ``seed``
    and the joint's index) with its own backlash, but the commands, the readings' stamps and
    the lost readings are shared, as when one controller sends one command array and one
    encoder message holds every joint. ``settings.model`` is replaced by each joint's.

    >>> from genbacklash_core.scenarios import OPERATION_BACKLASH, worn
    >>> recs = arm_records([OPERATION_BACKLASH, worn(OPERATION_BACKLASH, 2.0)],
    ...                    OperationSettings(duration=2.0), seed=3)
    >>> bool((recs[0].sample_t_ns == recs[1].sample_t_ns).all())
    True
    >>> bool((recs[0].command_u != recs[1].command_u).any())
    True
    """
    base = OperationSettings() if settings is None else settings
    if not isinstance(base, OperationSettings):
        raise GenBacklashError(f"settings must be OperationSettings, got {base!r}")
    if len(models) == 0:
        raise GenBacklashError("arm_records needs at least one model")
    out: list[OperationRecord] = []
    for j, model in enumerate(models):
        cfg = dataclasses.replace(base, model=model)
        values, phase_starts = operation_commands(np.random.default_rng([int(seed), 12, j]), cfg)
        clock = np.random.default_rng([int(seed), 13])  # the same clocks and losses for all
        out.append(_driven_record(clock, cfg, seed, values, phase_starts))
    return out
