"""One validated set of the node's parameters (:class:`NodeParameters`, checked against
:data:`~.specs.PARAMETER_SPECS`) and the settings of each stage it configures."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Literal

from genbacklash_core import (
    CompensatorOptions,
    GenBacklashError,
    OnlineIdentifier,
    RecursiveIdentifier,
    Structure,
    WindowedIdentifier,
)
from genbacklash_core.guard import GuardSettings
from genbacklash_core.measured import TrackingJudgeSettings
from genbacklash_core.servo import ServoModel
from genbacklash_ros.node.messages import CommandType, EncoderType
from genbacklash_ros.node.sample_rule import ServoChoice

from .specs import (
    COMPENSATOR_DEFAULTS,
    PAIRS,
    PARAMETER_SPECS,
    RECURSIVE_DEFAULTS,
    SPECS_BY_NAME,
    WINDOWED_DEFAULTS,
    ParameterValue,
    close_matches,
    pair_problem,
)


@dataclass(frozen=True)
class NodeParameters:
    """The validated parameters of the ``backlash_identifier`` node (see :data:`PARAMETER_SPECS`).

    Every field is checked against its spec in ``__post_init__`` (a
    :class:`~genbacklash_core.GenBacklashError` names the parameter and the allowed range),
    then the cross-checks: ``u_min < u_max`` and ``gate_low <= gate_high``.

    Examples
    --------
    >>> NodeParameters(gate_low=0.8, gate_high=0.5)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: parameter 'gate_low' (0.8) must not exceed ...
    >>> NodeParameters(model="cascade").structure()
    Structure(degree=3, na=2, nb=2, sign=1.0)
    """

    model: Literal["backlash", "cascade"] = "backlash"
    degree: int = 3
    na: int = 2
    nb: int = 2
    method: Literal["windowed", "recursive"] = "windowed"
    window: int = WINDOWED_DEFAULTS.window
    forgetting: float = RECURSIVE_DEFAULTS.forgetting
    joint: str = ""
    command_index: int = 0
    command_type: CommandType = "float64_multi_array"
    encoder_type: EncoderType = "joint_state"
    gear_input: Literal["command", "motor_encoder"] = "command"
    motor_encoder_type: EncoderType = "joint_state"
    motor_joint: str = ""
    compensate: bool = True
    compensation_in_loop: bool = False
    compensation_guard: bool = True
    u_min: float = -math.inf
    u_max: float = math.inf
    max_rate: float = math.inf
    gate_low: float = COMPENSATOR_DEFAULTS.gate_low
    gate_high: float = COMPENSATOR_DEFAULTS.gate_high
    checkpoint_file: str = ""
    checkpoint_period: float = 10.0
    publish_rate: float = 10.0
    settle_time: float = 0.005
    servo_model: Literal["none", "auto", "fixed"] = "none"
    servo_dead_time: float = 0.0
    servo_time_constant: float = 0.0
    servo_window: float = 5.0
    sample_period: float = 0.0
    stamp_source: Literal["header", "receive"] = "header"
    thread_priority: int = 0

    def __post_init__(self) -> None:
        for spec in PARAMETER_SPECS:
            object.__setattr__(self, spec.name, spec.check(getattr(self, spec.name)))
        for low, high in PAIRS:
            problem = pair_problem(low, getattr(self, low), high, getattr(self, high))
            if problem:
                raise GenBacklashError(problem)
        if self.gear_input == "motor_encoder" and self.sample_period:
            raise GenBacklashError(
                "parameter 'gear_input' motor_encoder pairs each encoder reading with the motor "
                "reading of its stamp: it needs sample_period 0 (one sample per encoder "
                f"reading), got sample_period {self.sample_period:g}"
            )

    @classmethod
    def from_mapping(cls, values: Mapping[str, object]) -> NodeParameters:
        """Parameters from a name -> value mapping; unset ones keep their defaults.

        Unknown names are an error that lists them with their close matches (a typo must
        not pass silently; all the names are in ``genbacklash replay --list-params``).

        >>> NodeParameters.from_mapping({"degre": 2})  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        genbacklash_core.errors.GenBacklashError: unknown parameter(s) 'degre' (close matches: ...)
        """
        unknown = sorted(str(k) for k in values if k not in SPECS_BY_NAME)
        if unknown:
            names = ", ".join(repr(k) for k in unknown)
            if len(unknown) == 1:
                hints = f" ({close_matches(unknown[0])})"
            else:
                hints = ": " + "; ".join(f"{k!r}: {close_matches(k)}" for k in unknown)
            raise GenBacklashError(f"unknown parameter(s) {names}{hints}")
        return cls(**values)  # type: ignore[arg-type]

    def replace(self, **changes: object) -> NodeParameters:
        """A validated copy with ``changes`` applied (for a set-parameters callback).

        >>> NodeParameters().replace(publish_rate=0.0)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        genbacklash_core.errors.GenBacklashError: parameter 'publish_rate' must lie in [0.01, ...
        """
        merged: dict[str, object] = dict(self.to_mapping())
        unknown = [k for k in changes if k not in SPECS_BY_NAME]
        if unknown:
            return NodeParameters.from_mapping(changes)  # raises, naming them
        merged.update(changes)
        return NodeParameters.from_mapping(merged)

    def to_mapping(self) -> dict[str, ParameterValue]:
        """Name -> value, in :data:`PARAMETER_SPECS` order."""
        return {spec.name: getattr(self, spec.name) for spec in PARAMETER_SPECS}

    def restart_needed(self, other: NodeParameters) -> bool:
        """True when going from ``self`` to ``other`` changes a parameter that restarts
        identification (see :attr:`ParameterSpec.restarts`)."""
        return any(
            getattr(self, s.name) != getattr(other, s.name) for s in PARAMETER_SPECS if s.restarts
        )

    def structure(self, sign: float = 1.0) -> Structure:
        """The model structure these parameters ask for (``na = nb = 0`` for a backlash)."""
        if self.model == "cascade":
            return Structure(self.degree, self.na, self.nb, sign)
        return Structure(self.degree, 0, 0, sign)

    def make_identifier(self, sign: float | None = None) -> OnlineIdentifier:
        """A fresh online identifier of the chosen ``method`` (non-finite samples dropped).

        ``sign`` is the branch sense when known (e.g. from a checkpoint); None detects it.
        """
        structure = self.structure()
        if self.method == "recursive":
            return RecursiveIdentifier(
                structure.degree,
                structure.na,
                structure.nb,
                sign=sign,
                settings=dataclasses.replace(
                    RECURSIVE_DEFAULTS, forgetting=self.forgetting, nonfinite="drop"
                ),
            )
        return WindowedIdentifier(
            structure.degree,
            structure.na,
            structure.nb,
            sign=sign,
            settings=dataclasses.replace(WINDOWED_DEFAULTS, window=self.window, nonfinite="drop"),
        )

    def compensator_options(self) -> CompensatorOptions:
        """Limits, rate limit and confidence gating of the compensator."""
        return CompensatorOptions(
            u_min=self.u_min,
            u_max=self.u_max,
            max_rate=self.max_rate,
            gate_low=self.gate_low,
            gate_high=self.gate_high,
        )

    def guard_settings(self) -> GuardSettings:
        """How the compensation guard judges (:class:`~genbacklash_core.guard.GuardSettings`)."""
        return GuardSettings(enabled=self.compensation_guard)

    def judge_settings(self) -> TrackingJudgeSettings:
        """How the measured tracking is judged
        (:class:`~genbacklash_core.measured.TrackingJudgeSettings`): its verdict counts only
        while the compensated command drives the drivetrain and the guard is on."""
        return TrackingJudgeSettings(in_loop=self.compensation_in_loop and self.compensation_guard)

    def servo(self) -> ServoChoice:
        """The servo the rows model (:mod:`genbacklash_core.servo`): None, ``"auto"`` or
        the fixed model. A cascade keeps the command as its input (None).

        >>> NodeParameters(servo_model="fixed", servo_dead_time=0.002).servo()
        ServoModel(dead_time=0.002, time_constant=0.0)
        """
        if self.model != "backlash" or self.servo_model == "none":
            return None
        if self.servo_model == "auto":
            return "auto"
        return ServoModel(self.servo_dead_time, self.servo_time_constant)

    @property
    def settle_ns(self) -> int:
        """``settle_time`` in integer nanoseconds."""
        return round(self.settle_time * 1e9)

    @property
    def motor_input(self) -> bool:
        """The gear's input is a motor encoder's reading (``gear_input``)."""
        return self.gear_input == "motor_encoder"

    @property
    def motor_joint_name(self) -> str:
        """The joint read from a motor encoder JointState: ``motor_joint``, else ``joint``."""
        return self.motor_joint or self.joint

    @property
    def sample_period_ns(self) -> int:
        """``sample_period`` in integer nanoseconds (0: sample at the encoder stamps)."""
        return round(self.sample_period * 1e9)

    @property
    def publish_period_ns(self) -> int:
        """Period of ``~/estimate`` in integer nanoseconds."""
        return max(round(1e9 / self.publish_rate), 1)

    @property
    def checkpoint_period_ns(self) -> int:
        """``checkpoint_period`` in integer nanoseconds."""
        return round(self.checkpoint_period * 1e9)


def resolve_requested(
    current: NodeParameters, requested: Mapping[str, object]
) -> tuple[NodeParameters, tuple[str, ...]]:
    """The parameters a running node applies when it holds the values ``requested``.

    The rule for changing parameters one at a time (``ros2 param set``, which sends one
    parameter per request): each value is checked on its own when it is set, and refused
    with the reason when it is invalid (a type, range or choice); the pairs of :data:`PAIRS`
    are checked on the values the node holds after the request. While a pair is
    inconsistent (the first of two ``ros2 param set`` that move it, in either order), both
    its values stay at ``current``'s and every other value applies; the pair applies as soon
    as it is consistent again. So a pair moves with two sets in any order, and the node never
    runs on an inconsistent pair.

    Parameters
    ----------
    current : NodeParameters
        What the node runs with now (always consistent).
    requested : mapping
        Name -> value the node holds (``current``'s values where not given); every value
        already valid on its own.

    Returns
    -------
    params : NodeParameters
        What to run with.
    pending : tuple of str
        One line per pair left at ``current``'s values: what is inconsistent and what is
        kept.

    Examples
    --------
    >>> now = NodeParameters()
    >>> params, pending = resolve_requested(now, {"gate_low": 0.7, "publish_rate": 5.0})
    >>> params.gate_low, params.publish_rate
    (0.2, 5.0)
    >>> print(pending[0])  # doctest: +NORMALIZE_WHITESPACE
    parameter 'gate_low' (0.7) must not exceed 'gate_high' (0.5): running on gate_low 0.2,
    gate_high 0.5 until the pair is consistent (set the other one next)
    >>> resolve_requested(now, {"gate_low": 0.7, "gate_high": 0.9})[0].gate_low
    0.7
    """
    merged: dict[str, object] = {**current.to_mapping(), **requested}
    pending: list[str] = []
    for low, high in PAIRS:
        problem = pair_problem(low, merged[low], high, merged[high])
        if problem:
            kept_low, kept_high = getattr(current, low), getattr(current, high)
            merged[low], merged[high] = kept_low, kept_high
            pending.append(
                f"{problem}: running on {low} {kept_low:g}, {high} {kept_high:g} until the "
                "pair is consistent (set the other one next)"
            )
    return NodeParameters.from_mapping(merged), tuple(pending)
