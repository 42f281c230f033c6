"""The motions of a drivetrain in operation (the module notes of
:mod:`genbacklash_core.scenarios`): trapezoidal moves, one-way traverses, pick and place and
sine sweeps, as held commands (:func:`operation_commands`).
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import FloatArray

from .settings import OperationSettings


def trapezoid(distance: float, v: float, a: float, dt: float) -> FloatArray:
    """Positions (from 0 to ``distance``) of a trapezoidal-velocity move, sampled every
    ``dt``, the last sample at the target."""
    d = abs(distance)
    if d == 0.0:
        return np.zeros(1)
    t_acc = v / a
    if a * t_acc * t_acc >= d:  # triangular: never reaches v
        t_acc = math.sqrt(d / a)
        v = a * t_acc
        t_flat = 0.0
    else:
        t_flat = (d - a * t_acc * t_acc) / v
    total = 2.0 * t_acc + t_flat
    t = np.arange(1, math.ceil(total / dt) + 1) * dt
    t = np.minimum(t, total)
    s = np.where(
        t < t_acc,
        0.5 * a * t * t,
        np.where(
            t < t_acc + t_flat,
            0.5 * a * t_acc * t_acc + v * (t - t_acc),
            d - 0.5 * a * np.square(np.maximum(total - t, 0.0)),
        ),
    )
    return np.asarray(math.copysign(1.0, distance) * s, dtype=np.float64)


def _operation(
    rng: np.random.Generator, cfg: OperationSettings, start: float, n: int, dt: float
) -> FloatArray:
    lo, hi = cfg.travel
    out: list[FloatArray] = []
    pos, last_dir, count = start, 1.0, 0
    while count < n:
        if rng.random() < cfg.jog_probability:
            step = -last_dir * rng.uniform(*cfg.jog_size)
            target = float(np.clip(pos + step, lo, hi))
        else:
            target = float(rng.uniform(lo, hi))
        if abs(target - pos) < 1e-3:
            target = float(np.clip(pos - last_dir * cfg.jog_size[1], lo, hi))
        v = cfg.v_max * rng.uniform(0.3, 1.0)
        path = pos + trapezoid(target - pos, v, cfg.a_max, dt)
        dwell = np.full(max(1, round(rng.uniform(*cfg.dwell) / dt)), target)
        out += [path, dwell]
        count += path.size + dwell.size
        last_dir = math.copysign(1.0, target - pos)
        pos = target
    return np.concatenate(out)[:n]


def _one_way(
    rng: np.random.Generator, cfg: OperationSettings, start: float, n: int, dt: float
) -> FloatArray:
    lo, hi = cfg.travel
    direction = 1.0 if (hi - start) >= (start - lo) else -1.0
    room = (hi - start) if direction > 0 else (start - lo)
    # speeds that vary smoothly, with stops; scaled to cover most of the room
    knots = rng.uniform(0.0, 1.0, max(2, n // 500 + 2))
    knots[rng.random(knots.size) < 0.25] = 0.0
    speed = np.interp(np.linspace(0, knots.size - 1, n), np.arange(knots.size), knots)
    path = np.cumsum(speed)
    if path[-1] > 0:
        path *= 0.9 * room / path[-1]
    return np.asarray(start + direction * path, dtype=np.float64)


def _pick_and_place(
    rng: np.random.Generator, cfg: OperationSettings, start: float, n: int, dt: float
) -> FloatArray:
    lo, hi = cfg.travel
    span = hi - lo
    pick, place = lo + 0.3 * span, lo + 0.65 * span
    out: list[FloatArray] = []
    pos, count, k = start, 0, 0
    while count < n:
        target = (pick if k % 2 == 0 else place) + rng.normal(0.0, 0.002)
        path = pos + trapezoid(target - pos, 0.8 * cfg.v_max, cfg.a_max, dt)
        dwell = np.full(max(1, round(rng.uniform(0.2, 0.4) / dt)), target)
        out += [path, dwell]
        count += path.size + dwell.size
        pos, k = target, k + 1
    return np.concatenate(out)[:n]


def _sine_sweep(
    rng: np.random.Generator, cfg: OperationSettings, start: float, n: int, dt: float
) -> FloatArray:
    lo, hi = cfg.travel
    centre, amplitude = 0.5 * (lo + hi), 0.45 * (hi - lo)
    t = np.arange(n) * dt
    duration = max(n * dt, dt)
    f0, f1 = 0.05, 0.5
    phase = 2.0 * math.pi * (f0 * t + 0.5 * (f1 - f0) * t * t / duration)  # linear chirp
    sweep = centre + amplitude * np.sin(phase)
    ramp = np.clip(t / 1.0, 0.0, 1.0)  # blend from the start position over 1 s
    return np.asarray((1.0 - ramp) * start + ramp * sweep, dtype=np.float64)


_MOTIONS = {
    "operation": _operation,
    "one_way": _one_way,
    "pick_and_place": _pick_and_place,
    "sine_sweep": _sine_sweep,
}


def operation_commands(
    rng: np.random.Generator, cfg: OperationSettings
) -> tuple[FloatArray, tuple[tuple[str, float], ...]]:
    """Command values at the nominal ticks of ``cfg.command_rate``, phase by phase, and each
    phase's kind and start (s); the first random draws of :func:`operation_record`."""
    dt = 1.0 / cfg.command_rate
    pos = 0.5 * (cfg.travel[0] + cfg.travel[1])
    pieces: list[FloatArray] = []
    starts: list[tuple[str, float]] = []
    elapsed = 0
    for kind, seconds in cfg.schedule:
        n = max(1, round(seconds * cfg.command_rate))
        piece = _MOTIONS[kind](rng, cfg, pos, n, dt)
        starts.append((kind, elapsed * dt))
        pieces.append(piece)
        pos = float(piece[-1])
        elapsed += n
    return np.clip(np.concatenate(pieces), *cfg.travel), tuple(starts)
