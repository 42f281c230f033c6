"""What a fleet run asks of each bag: the joints (:class:`JointRequest`) and the settings every
job runs with (:class:`FleetSettings`), with the hash that tells a stored result is still
valid.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from typing import Any

from genbacklash_core import (
    GenBacklashError,
)
from genbacklash_ros.node.parameters import NodeParameters


@dataclass(frozen=True)
class JointRequest:
    """A joint to analyse in each bag: its ``JointState`` name (``""``: the encoder's first
    joint) and the ``Float64MultiArray`` command element (None: the node parameter
    ``command_index``)."""

    name: str = ""
    command_index: int | None = None

    def __post_init__(self) -> None:
        if self.command_index is not None and self.command_index < 0:
            raise GenBacklashError(
                f"joint {self.name!r}: the command index must be >= 0, got {self.command_index}"
            )


def json_safe(value: Any) -> Any:
    """Non-finite floats as strings (``"inf"``), so that every database's JSON takes them."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


@dataclass(frozen=True)
class FleetSettings:
    """How each bag is analysed (the same for the whole archive).

    Attributes
    ----------
    command_topic, encoder_topic : str
        The topics read from every bag.
    params : NodeParameters
        The node's parameters: ``model``, ``degree``, ``na``, ``nb`` set the structure
        identified; ``joint``, ``command_index`` the joint when neither the path nor
        ``joints`` says; the replay uses them all.
    joints : tuple of JointRequest
        Joints to analyse in bags whose path and metadata name none (empty: ``params.joint``).
    diagnose : bool
        Run the discrepancy workflow.
    diagnose_from_params : bool
        The diagnosis starts from the structure in ``params`` (as ``genbacklash diagnose``
        does when ``model``/``degree``/``na``/``nb`` is given), else from the ideal backlash.
    validation : float
        Fraction of each record the diagnosis holds out.
    replay : bool
        Also replay the bag through the node's pipeline (the online estimate).
    max_nrmse : float
        A converged fit whose free-run NRMSE is above this is ``poor_fit``, not ``ok``.
    """

    command_topic: str = "/command"
    encoder_topic: str = "/encoder"
    params: NodeParameters = field(default_factory=NodeParameters)
    joints: tuple[JointRequest, ...] = ()
    diagnose: bool = True
    diagnose_from_params: bool = False
    validation: float = 0.3
    replay: bool = False
    max_nrmse: float = 0.02

    def __post_init__(self) -> None:
        if not self.command_topic or not self.encoder_topic:
            raise GenBacklashError("give both a command and an encoder topic")
        if self.command_topic == self.encoder_topic:
            raise GenBacklashError(
                f"the command and encoder topics must differ, both are {self.command_topic!r}"
            )
        if not 0.0 < self.validation < 1.0:
            raise GenBacklashError(f"validation must lie in (0, 1), got {self.validation}")
        if not self.max_nrmse > 0:
            raise GenBacklashError(f"max_nrmse must be > 0, got {self.max_nrmse}")

    def requests(self, path_joint: str | None) -> tuple[JointRequest, ...]:
        """The joints to analyse in a bag whose path or metadata names ``path_joint``."""
        if path_joint is not None:
            for request in self.joints:
                if request.name == path_joint:
                    return (request,)
            return (JointRequest(path_joint),)
        return self.joints or (JointRequest(self.params.joint),)

    def command_index(self, request: JointRequest) -> int:
        """The command element of ``request`` (the node parameter when it says none)."""
        if request.command_index is not None:
            return request.command_index
        return self.params.command_index

    def to_dict(self, joint: str, command_index: int) -> dict[str, Any]:
        """What decides one row's numbers (JSON values): the key of :meth:`key`."""
        params = dict(self.params.to_mapping())
        params.update(joint=joint, command_index=command_index)
        out: dict[str, Any] = json_safe(
            {
                "command_topic": self.command_topic,
                "encoder_topic": self.encoder_topic,
                "params": params,
                "diagnose": self.diagnose,
                "diagnose_from_params": self.diagnose_from_params,
                "validation": self.validation,
                "replay": self.replay,
                "max_nrmse": self.max_nrmse,
            }
        )
        return out

    def key(self, joint: str, command_index: int) -> str:
        """SHA-256 of :meth:`to_dict`: with the bag's hash and the joint, the row's identity
        (a re-run with the same key skips the bag).

        >>> FleetSettings().key("a", 0) == FleetSettings().key("a", 0) != FleetSettings(
        ...     replay=True).key("a", 0)
        True
        """
        text = json.dumps(self.to_dict(joint, command_index), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()
