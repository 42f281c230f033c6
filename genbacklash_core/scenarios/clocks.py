"""The clocks and the encoder of a drivetrain in operation: command and reading stamps
(:func:`timeline`) and what the encoder makes of the positions (:func:`readings`).
"""

from __future__ import annotations

import math

import numpy as np

from genbacklash_core._typing import BoolArray, FloatArray, IntArray


def timeline(
    rng: np.random.Generator,
    n_commands: int,
    *,
    command_rate: float,
    encoder_rate: float,
    command_jitter_ns: int,
    stamp_jitter_ns: float,
) -> tuple[IntArray, IntArray]:
    """The clocks of a drivetrain in operation (see the module notes): ``(command stamps,
    reading stamps)`` in ns from the start, for ``n_commands`` commands at the nominal ticks of
    ``command_rate`` (each up to ``command_jitter_ns`` late) and readings at ``encoder_rate``
    over the same span (Gaussian ``stamp_jitter_ns``, clipped to a third of the period, kept
    in order, the first not before the first command). Draws from ``rng`` in this order:
    command jitter, stamp jitter (each only when non-zero).

    >>> cmd_t, t = timeline(np.random.default_rng(0), 3, command_rate=100.0,
    ...                     encoder_rate=1000.0, command_jitter_ns=0, stamp_jitter_ns=0.0)
    >>> cmd_t.tolist(), t.size
    ([0, 10000000, 20000000], 30)
    """
    cmd_period = 1e9 / command_rate
    cmd_t = np.round(np.arange(n_commands) * cmd_period).astype(np.int64)
    if command_jitter_ns > 0:
        cmd_t += rng.integers(0, command_jitter_ns + 1, n_commands)
    total_ns = n_commands * cmd_period
    enc_period = 1e9 / encoder_rate
    n = math.floor(total_ns / enc_period)
    nominal = np.round(np.arange(n) * enc_period)
    jitter = rng.normal(0.0, stamp_jitter_ns, n) if stamp_jitter_ns > 0 else 0.0
    clip = enc_period / 3.0
    t = (nominal + np.clip(jitter, -clip, clip)).astype(np.int64)
    t[0] = max(int(t[0]), int(cmd_t[0]))  # the first reading after the first command
    return cmd_t, np.maximum.accumulate(t)


def readings(
    rng: np.random.Generator,
    x: FloatArray,
    *,
    noise: float = 0.0,
    quantum: float = 0.0,
    loss: float = 0.0,
) -> tuple[FloatArray, BoolArray]:
    """What an encoder makes of the positions ``x`` (see the module notes): ``(readings,
    received)``, white ``noise`` added, quantised to ``quantum``, each lost with probability
    ``loss`` (the first always received). Draws from ``rng`` in this order: noise (only when
    non-zero), loss (always).

    >>> y, ok = readings(np.random.default_rng(0), np.array([0.0, 0.26, 0.74]), quantum=0.5)
    >>> y.tolist(), ok.tolist()
    ([0.0, 0.5, 0.5], [True, True, True])
    """
    n = x.size
    y = x + (rng.normal(0.0, noise, n) if noise > 0 else 0.0)
    if quantum > 0:
        y = np.round(y / quantum) * quantum
    received = rng.random(n) >= loss
    received[0] = True
    return np.asarray(y, dtype=np.float64), received
