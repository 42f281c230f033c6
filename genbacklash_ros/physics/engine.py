"""Stepping the drivetrain: held commands in, motor and load trajectories out.

:class:`Drivetrain` owns one MuJoCo model and its state; :meth:`Drivetrain.hold` advances
it with one command held (the closed loop: a compensator can choose the next command from
what the encoder saw so far), :meth:`Drivetrain.follow` with a whole command sequence, and
:func:`simulate_commands` is the one-call form. Every step goes through
``mujoco.rollout`` (the steps run in C; the state and the solver's warm start carry over
between calls, so a run cut into pieces gives the same bits as one call).

A command stamped ``t`` acts from the first step that starts at or after ``t`` (a command
between step starts waits at most one step, 0.25 ms at 4 kHz). Positions are recorded at
the end of every step; :meth:`Trajectory.load_at` and :meth:`Trajectory.motor_at`
interpolate them linearly at any instant.

Examples
--------
>>> from genbacklash_ros.physics.variants import variant
>>> sim = Drivetrain(variant("near_ideal"))
>>> ramp = sim.advance(np.linspace(0.0, 0.1, 400)[1:])  # 0.1 rad in 0.1 s, then hold it
>>> part = sim.hold(0.1, 150_000_000)
>>> int(part.t_ns[-1]), round(float(part.motor[-1]), 4)  # the servo's static error
(150000000, 0.0995)
>>> round(float(part.load[-1]), 4)  # the load trails the motor by c_right (37.4 mrad)
0.062
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from genbacklash_core import GenBacklashError
from genbacklash_ros.physics.model import build_model
from genbacklash_ros.physics.variants import DrivetrainParameters

if TYPE_CHECKING:
    import mujoco

__all__ = ["DEFAULT_RATE", "Drivetrain", "Trajectory", "held_commands", "simulate_commands"]

DEFAULT_RATE = 4000.0
"""Steps per second of the integration."""


@dataclass(frozen=True, eq=False)
class Trajectory:
    """Positions at the end of each step (and at the start).

    Attributes
    ----------
    t_ns : ndarray of int
        Time of each row, ns from the simulation's start.
    command : ndarray
        The command in force during the step that ended at the row (the first row: the
        state's command before the first step).
    motor, slot, load : ndarray
        Rotor, slot hub and load angles, rad (``slot`` is ``load`` when rigid).
    torque : ndarray
        Servo torque during the step, N m.
    """

    t_ns: np.ndarray
    command: np.ndarray
    motor: np.ndarray
    slot: np.ndarray
    load: np.ndarray
    torque: np.ndarray

    def _at(self, values: np.ndarray, t_ns: np.ndarray) -> np.ndarray:
        t = np.asarray(t_ns, dtype=np.int64)
        if t.size and (t.min() < self.t_ns[0] or t.max() > self.t_ns[-1]):
            raise GenBacklashError(
                f"instants {t.min()}..{t.max()} ns outside the simulated "
                f"{self.t_ns[0]}..{self.t_ns[-1]} ns"
            )
        return np.asarray(
            np.interp(t.astype(np.float64), self.t_ns.astype(np.float64), values),
            dtype=np.float64,
        )

    def load_at(self, t_ns: np.ndarray) -> np.ndarray:
        """The load angle at ``t_ns`` (linear between steps)."""
        return self._at(self.load, t_ns)

    def motor_at(self, t_ns: np.ndarray) -> np.ndarray:
        """The rotor angle at ``t_ns`` (linear between steps)."""
        return self._at(self.motor, t_ns)

    @staticmethod
    def concatenate(parts: list[Trajectory]) -> Trajectory:
        """Pieces from consecutive calls as one (each piece's first row dropped after the
        first piece: it repeats the previous piece's last)."""
        if not parts:
            raise GenBacklashError("no trajectory pieces to join")

        def join(name: str) -> np.ndarray:
            first = getattr(parts[0], name)
            return np.concatenate([first, *(getattr(p, name)[1:] for p in parts[1:])])

        names = ("t_ns", "command", "motor", "slot", "load", "torque")
        return Trajectory(*(join(n) for n in names))


def held_commands(
    command_t_ns: np.ndarray, command_u: np.ndarray, step_t_ns: np.ndarray, before: float
) -> np.ndarray:
    """The command in force at each step start ``step_t_ns``: the last one stamped at or
    before it, ``before`` ahead of the first."""
    k = np.searchsorted(np.asarray(command_t_ns, dtype=np.int64), step_t_ns, side="right") - 1
    u = np.asarray(command_u, dtype=np.float64)
    return np.where(k >= 0, u[np.maximum(k, 0)], before)


class Drivetrain:
    """A physics drivetrain being stepped (see the module notes).

    Parameters
    ----------
    params : DrivetrainParameters
    rate : float
        Integration steps per second (>= 2000; the contact's time constant must span two).
    position : float
        Where it starts: motor and command at ``position``, the pin in the middle of the
        slot, everything at rest.
    """

    def __init__(
        self, params: DrivetrainParameters, *, rate: float = DEFAULT_RATE, position: float = 0.0
    ) -> None:
        import mujoco

        if not (isinstance(rate, (int, float)) and 2000.0 <= rate <= 100_000.0):
            raise GenBacklashError(f"rate must lie in [2000, 100000] steps/s, got {rate!r}")
        if params.contact_time < 2.0 / rate:
            raise GenBacklashError(
                f"contact_time {params.contact_time:g} s is below two steps at {rate:g} Hz"
            )
        self.params = params
        self.step_ns = round(1e9 / rate)
        self.model: mujoco.MjModel = build_model(params, timestep=self.step_ns / 1e9)
        self.data: mujoco.MjData = mujoco.MjData(self.model)
        self._spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
        self._nstate = int(mujoco.mj_stateSize(self.model, self._spec))
        self._q = [int(self.model.joint(name).qposadr[0]) for name in ("motor", "slot")]
        self._load_rel = None if params.rigid else int(self.model.joint("load").qposadr[0])
        self._steps = 0
        self.command = float(position)
        # at rest mid-slot: the pin at angle u - x = slot_offset from the load
        self.data.qpos[self._q[0]] = position
        self.data.qpos[self._q[1]] = position - params.slot_offset
        self.data.ctrl[0] = position
        mujoco.mj_forward(self.model, self.data)

    @property
    def time_ns(self) -> int:
        """Simulated time, ns."""
        return self._steps * self.step_ns

    def _state(self) -> np.ndarray:
        import mujoco

        state = np.empty(self._nstate)
        mujoco.mj_getState(self.model, self.data, state, self._spec)
        return state

    def _rows(self, states: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        qpos = states[:, 1 : 1 + self.model.nq]  # FULLPHYSICS: time, qpos, qvel, ...
        motor, slot = qpos[:, self._q[0]], qpos[:, self._q[1]]
        load = slot if self._load_rel is None else slot + qpos[:, self._load_rel]
        return motor, slot, load

    def advance(self, ctrl: np.ndarray) -> Trajectory:
        """Take ``ctrl.size`` steps, ``ctrl[k]`` the command during step ``k``; the rows:
        the state before, then after each step."""
        from mujoco import rollout

        ctrl = np.ascontiguousarray(ctrl, dtype=np.float64).reshape(-1)
        if not np.all(np.isfinite(ctrl)):
            raise GenBacklashError("commands must be finite")
        start = self._state()[None, :]
        before_command = self.command
        kp, kv = self.params.servo_gains()
        if ctrl.size:
            states, _ = rollout.rollout(
                self.model,
                self.data,
                start[0],
                ctrl[:, None],
                initial_warmstart=self.data.qacc_warmstart.copy(),
            )
            # rollout leaves self.data at the last state
            states = np.concatenate([start, states[0]])
            self.command = float(ctrl[-1])
        else:
            states = start
        motor, slot, load = self._rows(states)
        velocity = states[:, 1 + self.model.nq + self._q[0]]
        command = np.concatenate([[before_command], ctrl])
        # the actuator's force over each step, from the state at its start (MuJoCo's law)
        torque = np.clip(
            kp * (command[1:] - motor[:-1]) - kv * velocity[:-1],
            -self.params.torque_limit,
            self.params.torque_limit,
        )
        t = (self._steps + np.arange(ctrl.size + 1, dtype=np.int64)) * self.step_ns
        self._steps += ctrl.size
        return Trajectory(t, command, motor, slot, load, np.concatenate([[0.0], torque]))

    def hold(self, command: float, until_ns: int) -> Trajectory:
        """Hold ``command`` from now until the first step end at or after ``until_ns``."""
        n = max(0, -(-(int(until_ns) - self.time_ns) // self.step_ns))
        return self.advance(np.full(n, float(command)))

    def follow(self, command_t_ns: np.ndarray, command_u: np.ndarray, until_ns: int) -> Trajectory:
        """Run the commands (stamps in ns on this simulation's clock) until ``until_ns``,
        each held until the next (see the module notes)."""
        n = max(0, -(-(int(until_ns) - self.time_ns) // self.step_ns))
        starts = (self._steps + np.arange(n, dtype=np.int64)) * self.step_ns
        return self.advance(held_commands(command_t_ns, command_u, starts, self.command))


def simulate_commands(
    params: DrivetrainParameters,
    command_t_ns: np.ndarray,
    command_u: np.ndarray,
    until_ns: int,
    *,
    rate: float = DEFAULT_RATE,
) -> Trajectory:
    """Start ``params`` at rest at the first command and run the commands to ``until_ns``
    (:meth:`Drivetrain.follow`): the API benchmarks drive a compensated command with."""
    u = np.asarray(command_u, dtype=np.float64)
    if u.size == 0 or u.shape != np.shape(command_t_ns):
        raise GenBacklashError("give as many command stamps as values, at least one")
    sim = Drivetrain(params, rate=rate, position=float(u[0]))
    return sim.follow(np.asarray(command_t_ns, dtype=np.int64), u, until_ns)
