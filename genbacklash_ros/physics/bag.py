"""A physics drivetrain's record as a bag, with its truth in the metadata.

The same topics, types and log times as an operation scenario bag
(:func:`~genbacklash_ros.bags.simbags.write_operation_bag`, through
:func:`~genbacklash_ros.bags.simbags.write_record_bag`), so ``genbacklash replay`` and
``identify`` read it with ``--command /command --encoder /encoder``; with a motor encoder,
``/motor_encoder`` too. The truth (:class:`~genbacklash_ros.bags.simbags.BagTruth`, under
:data:`~genbacklash_ros.bags.simbags.TRUTH_KEY`) is the quasi-static characteristic against the
command (:func:`~genbacklash_ros.physics.truth.quasi_static`), constant over the record; its
``settings`` hold the operation settings and, under ``"physics"``, every drivetrain parameter,
the geometric play and dead zones, the quasi-static characteristics (against the command, the
motor, and the geometric one), the simulation rate and whether a motor encoder was written.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.simbags import (
    START_NS,
    TRUTH_KEY,
    TRUTH_STEP_S,
    BagTruth,
    SimulatedBag,
    phases_label,
    settings_dict,
    write_record_bag,
)
from genbacklash_ros.physics.engine import DEFAULT_RATE
from genbacklash_ros.physics.record import physics_record
from genbacklash_ros.physics.truth import quasi_static
from genbacklash_ros.physics.variants import DrivetrainParameters

__all__ = ["write_physics_bag"]


def write_physics_bag(
    path: str | Path,
    params: DrivetrainParameters,
    settings: OperationSettings | None = None,
    seed: int = 0,
    *,
    motor_encoder: bool = False,
    rate: float = DEFAULT_RATE,
) -> SimulatedBag:
    """Simulate ``params`` running ``settings`` (default 40 s of ``"operation"``) and write
    the bag directory ``path`` (see the module notes)."""
    cfg = OperationSettings(duration=40.0) if settings is None else settings
    sweep = quasi_static(params, cfg.travel, rate=rate)
    rec = physics_record(params, cfg, seed, rate=rate)
    label = f"physics:{params.name}:{phases_label(cfg)}"
    total = cfg.total_seconds
    end_s = rec.sample_t_ns[-1] / 1e9
    grid = np.arange(0.0, end_s, TRUTH_STEP_S)
    grid = np.append(grid, end_s) if end_s > grid[-1] else grid
    model = sweep.model
    physics = {
        "variant": params.name,
        "parameters": params.to_dict(),
        "geometric_play": params.play,
        "quasi_static": sweep.to_dict(),
        "rate": float(rate),
        "motor_encoder": bool(motor_encoder),
    }
    recorded = settings_dict(dataclasses.replace(cfg, model=model))
    recorded["physics"] = physics
    description = (
        f"{label}: {total:g} s of the physics drivetrain '{params.name}' ({params.description}); "
        f"servo {params.bandwidth:g} Hz, {params.torque_limit:g} N m; geometric play "
        f"{params.play:.4f} rad (c_L {params.c_left:.4f}, c_R {params.c_right:.4f}), "
        f"quasi-static c_L {model.c_left:.4f}, c_R {model.c_right:.4f} rad; commands "
        f"{cfg.command_rate:g} Hz held, encoder {cfg.encoder_rate:g} Hz ({cfg.counts_per_rev} "
        f"counts/rev, {cfg.loss:.0%} lost){', motor encoder' if motor_encoder else ''}; "
        f"seed {seed}"
    )
    truth = BagTruth(
        label,
        description,
        int(seed),
        START_NS,
        model,
        model,
        grid,
        np.full(grid.size, model.c_left),
        np.full(grid.size, model.c_right),
        rec.phase_starts,
        recorded,
    )
    custom = {TRUTH_KEY: truth.to_json()}
    counts = write_record_bag(
        path,
        custom,
        np.random.default_rng([int(seed), 21]),
        rec.command_t_ns,
        rec.command_u,
        rec.sample_t_ns,
        rec.received,
        rec.y_all,
        (rec.motor_y, rec.motor_received) if motor_encoder else None,
    )
    return SimulatedBag(Path(path), description, model, model, counts, total, custom)
