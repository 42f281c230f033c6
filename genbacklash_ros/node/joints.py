"""Several joints in one node: which joints, where their commands are, their parameters.

The node serves one joint by default (``joint``, ``command_index``). With ``joints`` (names
in the encoder's JointState) it serves each listed joint; an array command
(``command_type: float64_multi_array``) then needs ``command_indices``: one element index
per joint, in the same order. Every parameter of :data:`~genbacklash_ros.node.parameters.
PARAMETER_SPECS` set at the node's level applies to every joint; ``<joint>.<name>``
overrides it for one joint (a params file may nest it: ``shoulder: {degree: 2}`` is
``shoulder.degree``, as ROS 2 joins nested names). A node-wide ``checkpoint_file`` for
several joints must hold ``{joint}`` (replaced by each joint's name), or each joint names
its own: joints never share a file.

Not per joint: ``joint`` and ``command_index`` (``joints``, ``command_indices`` say them),
``command_type`` and ``encoder_type`` (one subscription each).

Examples
--------
>>> js = JointSet.from_mapping({"joints": ["shoulder", "elbow"], "command_indices": [0, 2],
...                             "degree": 2, "elbow.degree": 3})
>>> [(p.joint, p.command_index, p.degree) for p in js.per_joint]
[('shoulder', 0, 2), ('elbow', 2, 3)]
>>> JointSet.from_mapping({"degree": 2}).multi
False
>>> JointSet.from_mapping({"joints": ["a", "b"]})  # doctest: +ELLIPSIS
Traceback (most recent call last):
...
genbacklash_core.errors.GenBacklashError: parameter 'command_indices' must give one ...
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.parameters import (
    JOINT_KEYS,
    NODE_NAME,
    PARAMETER_SPECS,
    NodeParameters,
    is_joint_parameter,
    read_params_file,
)

__all__ = [
    "JOINT_KEYS",
    "NOT_PER_JOINT",
    "JointSet",
    "is_joint_parameter",
    "load_joint_set",
    "split_joint_names",
]

#: Parameters that cannot be set per joint (one subscription each, the joint's own place).
NOT_PER_JOINT = frozenset(
    {"joint", "command_index", "command_type", "encoder_type", "thread_priority"}
)
_SPEC_NAMES = frozenset(spec.name for spec in PARAMETER_SPECS)
_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_]*")
_JOINT_TOKEN = "{joint}"


def split_joint_names(text: str) -> tuple[str, ...]:
    """``"a,b, c"`` -> ``("a", "b", "c")`` (the command-line form of ``joints``).

    >>> split_joint_names("shoulder, elbow")
    ('shoulder', 'elbow')
    """
    return tuple(part.strip() for part in text.split(",") if part.strip())


def _names(value: object) -> tuple[str, ...]:
    if isinstance(value, str):
        names = split_joint_names(value)
    elif isinstance(value, Sequence) and all(isinstance(v, str) for v in value):
        names = tuple(str(v).strip() for v in value)
    else:
        raise GenBacklashError(f"parameter 'joints' must be a list of joint names, got {value!r}")
    for name in names:
        if not _NAME.fullmatch(name):
            raise GenBacklashError(
                f"parameter 'joints': {name!r} is not a joint name the node can serve (a "
                "letter, then letters, digits or '_': it names the topic ~/<joint>/estimate)"
            )
    if len(set(names)) != len(names):
        twice = sorted({n for n in names if names.count(n) > 1})
        raise GenBacklashError(f"parameter 'joints' lists {', '.join(twice)} more than once")
    return names


def _indices(value: object) -> tuple[int, ...]:
    if isinstance(value, str):
        parts = split_joint_names(value)
        try:
            items: Sequence[object] = [int(p) for p in parts]
        except ValueError as err:
            raise GenBacklashError(
                f"parameter 'command_indices' must be whole numbers, got {value!r}"
            ) from err
    elif isinstance(value, Sequence):
        items = value
    else:
        raise GenBacklashError(
            f"parameter 'command_indices' must be a list of whole numbers, got {value!r}"
        )
    out: list[int] = []
    for item in items:
        if isinstance(item, bool) or not isinstance(item, int) or not 0 <= item <= 65_535:
            raise GenBacklashError(
                f"parameter 'command_indices' must hold whole numbers in [0, 65535], got {item!r}"
            )
        out.append(item)
    if len(set(out)) != len(out):
        raise GenBacklashError(
            f"parameter 'command_indices' gives one element to two joints: {out}"
        )
    return tuple(out)


@dataclass(frozen=True)
class JointSet:
    """The joints one node serves and each joint's validated :class:`NodeParameters`.

    Attributes
    ----------
    base : NodeParameters
        The node-level parameters (the only ones in single-joint mode).
    joints : tuple of str
        ``joints`` (empty: single-joint mode, ``base.joint`` / ``base.command_index``).
    command_indices : tuple of int
        One per joint for an array command (empty otherwise).
    overrides : tuple of (str, str, value)
        The ``<joint>.<name>`` values, as ``(joint, name, value)``.
    per_joint : tuple of NodeParameters
        Computed: each joint's parameters (``joint`` and ``command_index`` its own); in
        single-joint mode ``(base,)``.
    """

    base: NodeParameters = field(default_factory=NodeParameters)
    joints: tuple[str, ...] = ()
    command_indices: tuple[int, ...] = ()
    overrides: tuple[tuple[str, str, Any], ...] = ()
    per_joint: tuple[NodeParameters, ...] = field(init=False)

    def __post_init__(self) -> None:
        base = self.base
        if not isinstance(base, NodeParameters):
            raise GenBacklashError(f"base must be NodeParameters, got {base!r}")
        object.__setattr__(self, "joints", _names(self.joints) if self.joints else ())
        object.__setattr__(
            self, "command_indices", _indices(self.command_indices) if self.command_indices else ()
        )
        if not self.joints:
            if self.command_indices or self.overrides:
                raise GenBacklashError(
                    "'command_indices' and '<joint>.<name>' parameters need 'joints'"
                )
            object.__setattr__(self, "per_joint", (base,))
            return
        self._check_node_level()
        object.__setattr__(self, "per_joint", tuple(self._joint_params(j) for j in self.joints))
        files = [p.checkpoint_file for p in self.per_joint if p.checkpoint_file]
        if len(set(files)) != len(files):
            raise GenBacklashError(
                "joints must not share a checkpoint_file: put '{joint}' in the node's "
                "checkpoint_file (replaced by each joint's name) or set <joint>.checkpoint_file"
            )

    def _check_node_level(self) -> None:
        base, n = self.base, len(self.joints)
        if base.joint or base.command_index:
            raise GenBacklashError(
                "with 'joints', leave 'joint' and 'command_index' unset: 'joints' and "
                "'command_indices' say each joint's name and element"
            )
        if base.gear_input != "command":
            raise GenBacklashError(
                "'joints' takes gear_input command only: a motor encoder as the gear's input "
                "is one joint per node (run one node per joint)"
            )
        if base.encoder_type != "joint_state":
            raise GenBacklashError(
                "'joints' needs encoder_type joint_state (the joints' readings by name)"
            )
        if base.command_type == "float64":
            raise GenBacklashError(
                "'joints' needs command_type float64_multi_array (with 'command_indices') or "
                "joint_state: a Float64 command holds one joint"
            )
        if base.command_type == "float64_multi_array" and len(self.command_indices) != n:
            raise GenBacklashError(
                f"parameter 'command_indices' must give one element index per joint ({n} "
                f"joints: {', '.join(self.joints)}), got {list(self.command_indices)}"
            )
        if base.command_type == "joint_state" and self.command_indices:
            raise GenBacklashError(
                "'command_indices' is for a float64_multi_array command; a joint_state "
                "command is read by the joint names"
            )
        for joint, name, _ in self.overrides:
            if joint not in self.joints:
                close = difflib.get_close_matches(joint, self.joints, n=3, cutoff=0.6)
                hint = f"close matches: {', '.join(close)}" if close else "no close match"
                raise GenBacklashError(
                    f"parameter '{joint}.{name}': {joint!r} is not in 'joints' ({hint})"
                )
            if name in NOT_PER_JOINT:
                raise GenBacklashError(
                    f"parameter '{joint}.{name}': {name!r} cannot be set per joint"
                )

    def _joint_params(self, joint: str) -> NodeParameters:
        base = self.base
        k = self.joints.index(joint)
        values: dict[str, object] = dict(base.to_mapping())
        values["joint"] = joint
        values["command_index"] = self.command_indices[k] if self.command_indices else 0
        if base.checkpoint_file:
            if _JOINT_TOKEN not in base.checkpoint_file and len(self.joints) > 1:
                raise GenBacklashError(
                    "with several joints, checkpoint_file must hold '{joint}' (replaced by "
                    "each joint's name) or be set per joint (<joint>.checkpoint_file)"
                )
            values["checkpoint_file"] = base.checkpoint_file.replace(_JOINT_TOKEN, joint)
        for name, value in ((n, v) for j, n, v in self.overrides if j == joint):
            values[name] = value
        try:
            return NodeParameters.from_mapping(values)
        except GenBacklashError as err:
            raise GenBacklashError(f"joint {joint!r}: {err}") from err

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_mapping(cls, values: Mapping[str, object]) -> JointSet:
        """A joint set from a flat name -> value mapping (a params file's, ``-p``'s).

        Names: those of :data:`PARAMETER_SPECS` (node level), ``joints``,
        ``command_indices`` and ``<joint>.<name>``; any other is an unknown parameter,
        named with its close matches.
        """
        node: dict[str, object] = {}
        overrides: list[tuple[str, str, Any]] = []
        for name, value in values.items():
            if name in JOINT_KEYS:
                continue
            joint, dot, rest = name.rpartition(".")
            if dot and joint and rest in _SPEC_NAMES:
                overrides.append((joint, rest, value))
            else:
                node[name] = value  # unknown names: NodeParameters names the close matches
        base = NodeParameters.from_mapping(node)
        return cls(
            base,
            _names(values["joints"]) if values.get("joints") else (),
            _indices(values["command_indices"]) if values.get("command_indices") else (),
            tuple(overrides),
        )

    @classmethod
    def single(cls, params: NodeParameters) -> JointSet:
        """Single-joint mode with ``params``."""
        return cls(params)

    # ------------------------------------------------------------------ views

    @property
    def multi(self) -> bool:
        """True when ``joints`` is set (one per-joint pipeline each)."""
        return bool(self.joints)

    @property
    def names(self) -> tuple[str, ...]:
        """The joints served (single-joint mode: ``(base.joint,)``, maybe ``('',)``)."""
        return self.joints if self.joints else (self.base.joint,)

    def to_mapping(self) -> dict[str, object]:
        """The flat mapping :meth:`from_mapping` reads (for a runtime change)."""
        out: dict[str, object] = dict(self.base.to_mapping())
        if self.joints:
            out["joints"] = list(self.joints)
        if self.command_indices:
            out["command_indices"] = list(self.command_indices)
        for joint, name, value in self.overrides:
            out[f"{joint}.{name}"] = value
        return out


def load_joint_set(
    path: str | Path, node_name: str = NODE_NAME, *, namespace: str | None = None
) -> JointSet:
    """A :class:`JointSet` from a ROS 2 params YAML (the sections that apply, as
    :func:`~genbacklash_ros.node.parameters.load_params_file` reads them); errors name the
    file."""
    values = read_params_file(path, node_name, namespace=namespace)
    try:
        return JointSet.from_mapping(values)
    except GenBacklashError as err:
        raise GenBacklashError(f"params file {Path(path)}: {err}") from err
