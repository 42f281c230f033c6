"""The simulated arm of ``genbacklash demo --live``: physics drivetrains that obey commands.

Each joint is a physics drivetrain (:class:`~genbacklash_ros.physics.engine.Drivetrain`: a
position servo, the play as contact, the load's inertia and friction; a variant of
:mod:`genbacklash_ros.physics.variants`). A joint moves as a drivetrain in operation does
(:func:`~genbacklash_core.scenarios.operation_commands`: trapezoidal moves, dwells, jogs),
its own seed per joint. The arm *obeys* the commands it is sent (the identifier node's
``compensated_command``); a twin of every drivetrain runs beside it on the *desired* commands
themselves, taken at the moment the arm takes the compensated answer to them (the same delay
for both), so what compensation changes is measured live: the RMS load tracking error (load
minus the desired command now) of each, per joint.

A second, *perturbed* twin takes the same desired commands as the first, its load started
:data:`PERTURB` of the play away: what it and the first twin differ by is the comparison's own
spread (a load that coasts in the play parts from its twin once it sits elsewhere in it), and
the readings taken while the arm held a command other than the desired one (and
:data:`~genbacklash_ros.demo.verdict.SETTLE_S` after) are counted apart: where compensation
acted (:mod:`genbacklash_ros.demo.verdict`).

No ROS here: :mod:`genbacklash_ros.demo.live` puts it on topics.

Examples
--------
>>> arm = SimulatedArm(ArmSettings(joints=("a",), duration=1.0))  # doctest: +SKIP
>>> arm.desired(0)  # doctest: +SKIP
(0.0,)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from genbacklash_core import GenBacklashError
from genbacklash_core.scenarios import OperationSettings, operation_commands
from genbacklash_ros.demo.verdict import SETTLE_S, Comparison, DemoVerdict

if TYPE_CHECKING:  # the engine needs mujoco: imported when an arm is made
    from genbacklash_ros.physics.engine import Drivetrain, Trajectory

__all__ = ["PERTURB", "ArmSettings", "JointErrors", "SimulatedArm"]

PERTURB = 0.25
"""The perturbed twin's load starts this share of the play away from the others' (its motor
and command start that far off; the first command takes the motor back, the load stays)."""


@dataclass(frozen=True)
class ArmSettings:
    """What the live demo simulates.

    Attributes
    ----------
    joints : tuple of str
        Joint names (the JointState's names and the command array's order).
    variant : str
        Physics drivetrain of every joint (``near_ideal``, ``coasting``, ``compliant``,
        ``gravity``).
    bandwidth : float
        Servo bandwidth, Hz.
    duration : float
        Seconds of motion.
    command_rate, encoder_rate : float
        Commands and JointState messages per second.
    seed : int
        Joint ``k`` moves with seed ``seed + k``.
    """

    joints: tuple[str, ...] = ("joint_1",)
    variant: str = "near_ideal"
    bandwidth: float = 60.0
    duration: float = 40.0
    command_rate: float = 100.0
    encoder_rate: float = 500.0
    seed: int = 0

    def __post_init__(self) -> None:
        if not self.joints or len(set(self.joints)) != len(self.joints):
            raise GenBacklashError(f"joints must be distinct names, got {self.joints!r}")
        if not 1.0 <= self.duration <= 3600.0:
            raise GenBacklashError(f"duration must lie in [1, 3600] s, got {self.duration!r}")
        if not 10.0 <= self.command_rate <= 1000.0:
            raise GenBacklashError(
                f"command_rate must lie in [10, 1000] Hz, got {self.command_rate!r}"
            )
        if not self.command_rate <= self.encoder_rate <= 2000.0:
            raise GenBacklashError(
                f"encoder_rate must lie between command_rate and 2000 Hz, got {self.encoder_rate!r}"
            )


@dataclass
class JointErrors:
    """Squared tracking errors of one joint, summed (obeyed arm, uncompensated twin and
    perturbed twin)."""

    obeyed: float = 0.0
    twin: float = 0.0
    perturbed: float = 0.0
    count: int = 0

    def add(self, obeyed: float, twin: float, perturbed: float) -> None:
        self.obeyed += obeyed * obeyed
        self.twin += twin * twin
        self.perturbed += perturbed * perturbed
        self.count += 1

    def rms(self) -> tuple[float, float]:
        """``(obeyed, twin)`` RMS errors, NaN when empty."""
        errors = self.comparison(1.0)
        return errors.arm, errors.twin

    def comparison(self, rate: float) -> Comparison:
        """The three RMS errors (NaN when empty) over ``count / rate`` seconds."""
        if not self.count:
            return Comparison(math.nan, math.nan, math.nan, 0.0)
        n = self.count
        return Comparison(
            math.sqrt(self.obeyed / n),
            math.sqrt(self.twin / n),
            math.sqrt(self.perturbed / n),
            n / rate,
        )


@dataclass
class _Joint:
    desired: np.ndarray
    arm: Drivetrain
    twin: Drivetrain
    perturbed: Drivetrain
    arm_part: Trajectory | None = None  # the last stretch stepped
    twin_part: Trajectory | None = None
    perturbed_part: Trajectory | None = None
    window: JointErrors = field(default_factory=JointErrors)
    late: JointErrors = field(default_factory=JointErrors)  # the second half of the motion
    acted: JointErrors = field(default_factory=JointErrors)  # while compensation acted
    acted_until: int = -1  # readings up to this time (ns) count as acted


class SimulatedArm:
    """Physics drivetrains for every joint, each with a twin on the desired commands.

    Parameters
    ----------
    settings : ArmSettings
    """

    def __init__(self, settings: ArmSettings) -> None:
        from genbacklash_ros.physics.engine import Drivetrain
        from genbacklash_ros.physics.variants import variant

        self.settings = settings
        self.params = variant(settings.variant, bandwidth=settings.bandwidth)
        cfg = OperationSettings(
            duration=settings.duration,
            phases=(("operation", settings.duration),),
            command_rate=settings.command_rate,
        )
        self.travel = cfg.travel
        self._joints: list[_Joint] = []
        for k, _ in enumerate(settings.joints):
            desired, _ = operation_commands(np.random.default_rng(settings.seed + k), cfg)
            start = float(desired[0])
            self._joints.append(
                _Joint(
                    desired,
                    Drivetrain(self.params, position=start),
                    Drivetrain(self.params, position=start),
                    Drivetrain(self.params, position=start + PERTURB * self.params.play),
                )
            )
        self.commands = min(j.desired.size for j in self._joints)
        self.obeyed = [float(j.desired[0]) for j in self._joints]  # the command in force
        self.twin_tick = 0  # the desired command the twins hold
        self.step_to(0)

    @property
    def play(self) -> float:
        """The geometric play of every joint's drivetrain, rad."""
        return float(self.params.play)

    def desired(self, tick: int) -> tuple[float, ...]:
        """The desired command of every joint at command tick ``tick``."""
        k = min(max(tick, 0), self.commands - 1)
        return tuple(float(j.desired[k]) for j in self._joints)

    def obey(self, values: tuple[float, ...] | list[float], tick: int) -> None:
        """The compensated answer to command ``tick`` arrived, a value for every joint: the
        arm holds it from now, the twins the desired command ``tick``."""
        if len(values) < len(self._joints):
            raise GenBacklashError(
                f"a command for {len(self._joints)} joints needs as many values, got {len(values)}"
            )
        self.obeyed = [float(v) for v in values[: len(self._joints)]]
        self.twin_tick = tick

    def step_to(self, until_ns: int) -> None:
        """Step every drivetrain to ``until_ns`` (the arm on the command it obeys, the twin
        on the desired command it holds), keeping the stretch for :meth:`loads_at`. One
        stretch per command period, not per reading: a MuJoCo rollout call costs far more
        than its few steps."""
        held = self.desired(self.twin_tick)
        for j, obeyed, twin_u in zip(self._joints, self.obeyed, held, strict=True):
            j.arm_part = j.arm.hold(obeyed, until_ns)
            j.twin_part = j.twin.hold(twin_u, until_ns)
            j.perturbed_part = j.perturbed.hold(twin_u, until_ns)

    def loads_at(self, t_ns: int, tick: int) -> tuple[float, ...]:
        """The arm's load positions at ``t_ns`` (inside the last stretch), and the three
        loads' errors against the desired command of ``tick`` (the one in force) counted;
        apart while compensation acts (the arm holds a command other than the twins',
        and :data:`~genbacklash_ros.demo.verdict.SETTLE_S` after)."""
        desired = self.desired(tick)
        held = self.desired(self.twin_tick)
        late = tick >= self.commands // 2
        at = np.array([t_ns], dtype=np.int64)
        settle = round(SETTLE_S * 1e9)
        loads = []
        for j, want, obeyed, twin_u in zip(self._joints, desired, self.obeyed, held, strict=True):
            a, b, c = j.arm_part, j.twin_part, j.perturbed_part
            assert a is not None and b is not None and c is not None  # stepped at __init__
            load, twin, other = (float(part.load_at(at)[0]) for part in (a, b, c))
            errors = (load - want, twin - want, other - want)
            j.window.add(*errors)
            if late:
                j.late.add(*errors)
            if obeyed != twin_u:
                j.acted_until = t_ns + settle
            if t_ns <= j.acted_until:
                j.acted.add(*errors)
            loads.append(load)
        return tuple(loads)

    def window(self) -> list[tuple[float, float]]:
        """Per joint, the ``(obeyed, twin)`` RMS errors since the last call (then reset)."""
        out = []
        for j in self._joints:
            out.append(j.window.rms())
            j.window = JointErrors()
        return out

    def second_half(self) -> list[tuple[float, float]]:
        """Per joint, the ``(obeyed, twin)`` RMS errors over the second half of the motion."""
        return [j.late.rms() for j in self._joints]

    def verdicts(self) -> list[DemoVerdict]:
        """Per joint, the verdict on the second half and on the readings while compensation
        acted (:mod:`genbacklash_ros.demo.verdict`)."""
        rate = self.settings.encoder_rate
        return [
            DemoVerdict(j.late.comparison(rate), j.acted.comparison(rate)) for j in self._joints
        ]
