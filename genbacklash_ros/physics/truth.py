"""The truth of a physics drivetrain: its geometric play and its quasi-static characteristic.

The geometric play is what the model is built from (:attr:`DrivetrainParameters.play`, split
into ``c_left``, ``c_right`` by the slot's offset). The quasi-static characteristic is
measured in the simulator, as one would on a test bench: the command ramps slowly (a
triangle at ``speed`` rad/s, commands at every step, no 100 Hz hold) from the middle of the
travel up to its top, down to its bottom and back, and the load angle is read against the
command (and against the motor angle). A ramp is not yet static: the servo trails a ramp by
``kv v / kp = 2 v / omega_n`` and the viscous terms grow with ``v``, all linearly in the
speed, so the sweep runs at ``speed`` and at ``2 speed`` and each parameter is extrapolated
to zero speed, ``p(0) = 2 p(v) - p(2 v)``. A branch is the part of a sweep where the pin
presses the flank that direction drives (found from the pin's angle in the slot, which the
contact's penetration moves by micro-radians only) and has pressed it for ``settle``
seconds; a straight line fitted to it gives the project's parameters (eqs. 11-12 with
``n = 1``): ``x = m_R1 (u - c_R)`` going up, ``x = m_L1 (u + c_L)`` going down. Where the
load is held on the other flank (gravity), the samples belong to neither branch;
:attr:`QuasiStatic.held_share` says over how much of the sweep that happened.

Against the command the dead zones include the servo's static error under the load's
friction (``load_friction / kp`` a side); against the motor angle they do not; a compliant
coupling adds its wind-up, ``load_friction / coupling_stiffness`` a side, to both.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from genbacklash_core import GenBacklashError, GeneralBacklash
from genbacklash_ros.physics.engine import DEFAULT_RATE, Drivetrain
from genbacklash_ros.physics.variants import DrivetrainParameters

__all__ = ["QuasiStatic", "quasi_static"]


@dataclass(frozen=True)
class QuasiStatic:
    """A slow sweep's characteristic (see the module notes).

    Attributes
    ----------
    model : GeneralBacklash
        Load angle against the command, degree 1.
    motor_model : GeneralBacklash
        Load angle against the motor angle, degree 1.
    geometric : GeneralBacklash
        The geometric play: slopes 1, ``c_left``, ``c_right`` of the parameters.
    held_share : float
        Share of the (slower) downward sweep with the load held on the upward branch's
        flank.
    samples : (int, int)
        Samples of the left (down) and right (up) branch fits of the slower sweep.
    speed : float
        The slower sweep's speed, rad/s (the other ran at twice that).
    """

    model: GeneralBacklash
    motor_model: GeneralBacklash
    geometric: GeneralBacklash
    held_share: float
    samples: tuple[int, int]
    speed: float

    @property
    def play(self) -> float:
        """``c_left + c_right`` of :attr:`model` (rad)."""
        return self.model.c_left + self.model.c_right

    def to_dict(self) -> dict[str, object]:
        """JSON values: the three models' parameters and the sweep's figures."""

        def plain(m: GeneralBacklash) -> dict[str, object]:
            return {
                "m_left": list(m.m_left),
                "c_left": m.c_left,
                "m_right": list(m.m_right),
                "c_right": m.c_right,
            }

        return {
            "command": plain(self.model),
            "motor": plain(self.motor_model),
            "geometric": plain(self.geometric),
            "held_share": self.held_share,
            "samples": list(self.samples),
            "speed": self.speed,
        }


def _line(u: np.ndarray, x: np.ndarray, side: str) -> tuple[float, float]:
    """``(slope, c)`` of the branch through ``(u, x)``: ``x = m (u + c)`` on the left,
    ``x = m (u - c)`` on the right."""
    if u.size < 10 or np.ptp(u) <= 0.0:
        raise GenBacklashError(f"the sweep never engaged the {side} branch")
    slope, intercept = np.polyfit(u, x, 1)
    c = intercept / slope if side == "left" else -intercept / slope
    return float(slope), float(c)


def _sweep(
    params: DrivetrainParameters,
    travel: tuple[float, float],
    speed: float,
    settle: float,
    rate: float,
    decimate: int,
) -> tuple[np.ndarray, float, tuple[int, int]]:
    """One sweep at ``speed``: ``(parameters, held share, samples)``, the parameters
    ``[m_L1, c_L, m_R1, c_R]`` against the command then against the motor."""
    lo, hi = travel
    mid = 0.5 * (lo + hi)
    sim = Drivetrain(params, rate=rate, position=mid)
    dt = sim.step_ns / 1e9
    legs = np.concatenate(
        [
            np.linspace(mid, hi, max(2, round((hi - mid) / speed / dt))),
            np.linspace(hi, lo, max(2, round((hi - lo) / speed / dt)))[1:],
            np.linspace(lo, mid, max(2, round((mid - lo) / speed / dt)))[1:],
        ]
    )
    run = sim.advance(legs)
    u, motor, slot, load = (a[1::decimate] for a in (run.command, run.motor, run.slot, run.load))
    direction = np.sign(np.diff(u, prepend=u[0]))
    # the pin's angle in the slot: slot_offset +- play / 2 on the flanks
    pin = motor - slot - params.slot_offset
    tolerance = 0.05 * params.play
    on_high = pin > params.play / 2.0 - tolerance  # the flank an upward move drives
    on_low = pin < -params.play / 2.0 + tolerance
    keep = max(1, round(settle / (dt * decimate)))

    def settled(mask: np.ndarray) -> np.ndarray:
        # engaged for `keep` samples in a row
        run_length = np.zeros(mask.size, dtype=np.int64)
        count = 0
        for i, flag in enumerate(mask.tolist()):
            count = count + 1 if flag else 0
            run_length[i] = count
        return run_length >= keep

    up = settled((direction > 0) & on_high)
    down = settled((direction < 0) & on_low)
    held = float(np.mean(on_high[direction < 0])) if np.any(direction < 0) else 0.0
    m_r, c_r = _line(u[up], load[up], "right")
    m_l, c_l = _line(u[down], load[down], "left")
    mm_r, cm_r = _line(motor[up], load[up], "right")
    mm_l, cm_l = _line(motor[down], load[down], "left")
    samples = (int(down.sum()), int(up.sum()))
    return np.array([m_l, c_l, m_r, c_r, mm_l, cm_l, mm_r, cm_r]), held, samples


def quasi_static(
    params: DrivetrainParameters,
    travel: tuple[float, float] = (-1.2, 1.2),
    *,
    speed: float = 0.25,
    settle: float = 0.1,
    rate: float = DEFAULT_RATE,
    decimate: int = 4,
) -> QuasiStatic:
    """Measure the quasi-static characteristic of ``params`` over ``travel`` (see the module
    notes): sweeps at ``speed`` and ``2 speed`` rad/s, extrapolated to zero speed; a branch
    counts once its flank has been pressed for ``settle`` s; ``decimate``: keep every that
    many steps.

    >>> from genbacklash_ros.physics.variants import variant
    >>> q = quasi_static(variant("near_ideal"), (-0.3, 0.3))
    >>> round(q.motor_model.c_left + q.motor_model.c_right, 4)  # the geometric 0.0698
    0.0698
    """
    if not (travel[0] < travel[1] and speed > 0.0 and settle >= 0.0 and decimate >= 1):
        raise GenBacklashError("quasi_static needs lo < hi, speed > 0, settle >= 0, decimate >= 1")
    slow, held, samples = _sweep(params, travel, speed, settle, rate, decimate)
    fast, _, _ = _sweep(params, travel, 2.0 * speed, settle, rate, decimate)
    p = 2.0 * slow - fast  # linear in the speed: p(0) = 2 p(v) - p(2 v)
    return QuasiStatic(
        model=GeneralBacklash((p[0],), p[1], (p[2],), p[3]),
        motor_model=GeneralBacklash((p[4],), p[5], (p[6],), p[7]),
        geometric=GeneralBacklash((1.0,), params.c_left, (1.0,), params.c_right),
        held_share=held,
        samples=samples,
        speed=float(speed),
    )
