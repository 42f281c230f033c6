"""The ``--ros-args`` part of a node's command line (``-p``, ``--params-file``, ``-r``): read
the way ``rclpy`` reads it, checked against the parameters the node knows."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from genbacklash_core import (
    GenBacklashError,
)

from .params_file import section_matches
from .specs import NODE_NAME, SPECS_BY_NAME, is_joint_parameter, is_standard, unknown_name

# --------------------------------------------------------------------------- ROS arguments


@dataclass(frozen=True)
class RosArguments:
    """What a node's ``--ros-args`` say about its parameters: the params files in order, and
    the namespace and name they are matched against.

    Attributes
    ----------
    params_files : tuple of str
    parameters : tuple of (str, str, str)
        The ``-p``/``--param`` rules in order as ``(node, name, value)``: ``node`` is the
        node-name prefix of ``-p node:name:=value`` (``""`` without one: every node), ``value``
        the YAML text.
    namespace : str
        From ``-r __ns:=/arm`` (``""``: the root namespace).
    node_name : str
        From ``-r __node:=name`` (default :data:`NODE_NAME`).
    """

    params_files: tuple[str, ...] = ()
    namespace: str = ""
    node_name: str = NODE_NAME
    parameters: tuple[tuple[str, str, str], ...] = ()

    def node_parameters(self) -> dict[str, str]:
        """Name -> value text of the ``-p`` rules that apply to this node (rules without a
        node prefix, and those whose prefix matches the node as a params-file section key
        would), later rules winning."""
        chosen: dict[str, str] = {}
        for node, name, value in self.parameters:
            if node:
                try:
                    applies, _ = section_matches(node, self.node_name, self.namespace, Path("-p"))
                except GenBacklashError:  # not a node name rcl accepts: rcl says so itself
                    continue
                if not applies:
                    continue
            chosen[name] = value
        return chosen

    def check_parameter_names(self) -> None:
        """Refuse a ``-p`` name the node does not have, naming the close matches (a typo must
        not pass silently: rcl takes any name, and the node would ignore it).

        >>> parse_ros_arguments(["n", "--ros-args", "-p", "degre:=2"]).check_parameter_names()
        Traceback (most recent call last):
        ...
        genbacklash_core.errors.GenBacklashError: -p: unknown parameter 'degre' (close matches: ...)
        """
        for name in self.node_parameters():
            if name not in SPECS_BY_NAME and not is_standard(name) and not is_joint_parameter(name):
                raise GenBacklashError(unknown_name(name, "-p"))


_ROS_OPTIONS_WITH_VALUE = frozenset(
    {"-r", "--remap", "-p", "--param", "--params-file", "-e", "--enclave", "--log-level"}
    | {"--log-config-file", "--log-file-name"}
)


def parse_ros_arguments(argv: Sequence[str]) -> RosArguments:
    """The params files, namespace and node name in a command line's ``--ros-args``
    sections (each up to ``--`` or the next ``--ros-args``), as rcl reads them.

    >>> ros = parse_ros_arguments(["node", "--ros-args", "-r", "__ns:=/arm", "--params-file",
    ...     "a.yaml", "-p", "degree:=2", "--", "x", "--ros-args", "--params-file", "b.yaml"])
    >>> ros.params_files, ros.namespace, ros.node_name
    (('a.yaml', 'b.yaml'), '/arm', 'backlash_identifier')
    """
    files: list[str] = []
    rules: list[tuple[str, str, str]] = []
    namespace = ""
    node_name = NODE_NAME
    inside = False
    items = iter(argv)
    for item in items:
        if item == "--ros-args":
            inside = True
            continue
        if not inside:
            continue
        if item == "--":
            inside = False
            continue
        if item not in _ROS_OPTIONS_WITH_VALUE:
            continue
        value = next(items, "")
        if item == "--params-file":
            files.append(value)
        elif item in ("-p", "--param"):
            target, sep, text = value.partition(":=")
            if sep:  # (rcl refuses a rule without ':=' itself)
                node, _, name = target.rpartition(":")
                rules.append((node, name, text))
        elif item in ("-r", "--remap"):
            source, _, target = value.partition(":=")
            source = source.rsplit(":", 1)[-1]  # node-specific remaps: `name:__ns:=...`
            if source == "__ns":
                namespace = target
            elif source in ("__node", "__name"):
                node_name = target
    return RosArguments(tuple(files), namespace, node_name, tuple(rules))
