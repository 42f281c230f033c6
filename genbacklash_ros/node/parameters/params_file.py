"""ROS 2 parameters YAML: the node's section of a params file (``/**``, its name, its
namespace) read into :class:`~.values.NodeParameters`."""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from genbacklash_core import (
    GenBacklashError,
)

from .specs import NODE_NAME, SPECS_BY_NAME, STANDARD_NAMES, STANDARD_PREFIXES, is_joint_parameter
from .values import NodeParameters

# --------------------------------------------------------------------------- params YAML


def _flatten(prefix: str, values: Mapping[Any, Any]) -> Iterator[tuple[str, object]]:
    """``{"a": {"b": 1}}`` -> ``("a.b", 1)``: ROS 2 nests dotted parameter names."""
    for key, value in values.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            yield from _flatten(f"{name}.", value)
        else:
            yield name, value


_TOKEN = re.compile(r"[A-Za-z0-9_]+")


def _section_pattern(key: str, file: Path) -> re.Pattern[str]:
    """The regular expression rcl matches a node's fully qualified name against, for one
    top-level key of a params file.

    rcl puts a ``/`` before a key without one; ``/**`` stands for any number of namespace
    tokens (none included) and ``/*`` for exactly one token. Tokens are alphanumerics and
    ``_``, or a whole ``*`` / ``**``: rcl refuses the file otherwise (``backlash_*``), and so
    does this reader. Checked against rcl on this machine (tests/ros/node/test_parameters.py).
    """
    tokens = key.strip().lstrip("/").split("/")
    regex = ""
    for token in tokens:
        if token == "**":
            regex += "(?:/[A-Za-z0-9_]+)*"
        elif token == "*":
            regex += "/[A-Za-z0-9_]+"
        elif _TOKEN.fullmatch(token):
            regex += "/" + token
        else:
            raise GenBacklashError(
                f"params file {file}: section {key!r} is not a node name ROS 2 accepts "
                "(names of alphanumerics and '_' separated by '/', or a whole '*' or '**'; "
                "e.g. '/**/backlash_identifier')"
            )
    return re.compile(regex)


def section_matches(
    key: str, node_name: str, namespace: str | None, file: Path
) -> tuple[bool, bool]:
    """``(applies, specific)``: whether a top-level YAML key applies to the node, and whether
    it is addressed to the node by name (its last token is the node's name, e.g.
    ``backlash_identifier``, ``/arm/backlash_identifier``, ``/**/backlash_identifier``)
    rather than to every node (``/**``, ``/arm/*``).

    With a ``namespace`` the key applies as rcl applies it to the node
    ``/<namespace>/<node_name>`` (``backlash_identifier:`` is ``/backlash_identifier`` and
    does not apply under a namespace; ``/**/backlash_identifier:`` and ``/**:`` do). With
    ``namespace=None`` (tools without a namespace: replay, identify, diagnose) it applies
    when it would in some namespace.
    """
    pattern = _section_pattern(key, file)
    last = key.strip().rstrip("/").rsplit("/", 1)[-1]
    specific = last == node_name
    if namespace is None:
        return specific or last in ("*", "**"), specific
    inner = namespace.strip("/")
    fqn = f"/{inner}/{node_name}" if inner else f"/{node_name}"
    return pattern.fullmatch(fqn) is not None, specific


def read_params_file(
    path: str | Path, node_name: str = NODE_NAME, *, namespace: str | None = None
) -> dict[str, object]:
    """The parameters a ROS 2 params YAML sets for ``node_name``, merged in file order.

    A section applies to the node ``/<namespace>/<node_name>`` as rcl decides it (see
    :func:`section_matches`: ``/**``, ``/**/backlash_identifier``, ``/arm/backlash_identifier``,
    ``/arm/*``, ...; ``namespace=None``: in any namespace); each holds ``ros__parameters``
    (nested keys are joined with dots, as ROS does). Later sections override earlier ones.
    Parameters every node has (``use_sim_time``, ``qos_overrides.*``) are left out. Names
    from sections addressed to every node (``/**``) that this node does not know are
    ignored (they may be meant for other nodes); names in a section that names the node are
    kept, so that :func:`load_params_file` reports them.
    """
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except OSError as err:
        raise GenBacklashError(f"cannot read params file {file}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise GenBacklashError(f"params file {file} is not UTF-8 text: {err}") from err
    import yaml  # here: a replay without a params file does not pay for the import

    try:
        document = yaml.safe_load(text)
    except yaml.YAMLError as err:
        where = getattr(err, "problem_mark", None)
        line = f" (line {where.line + 1})" if where is not None else ""
        # the parser's problem alone: its message also quotes the line over several lines
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise GenBacklashError(f"params file {file} is not valid YAML{line}: {problem}") from err
    if document is None:
        return {}
    if not isinstance(document, Mapping):
        raise GenBacklashError(
            f"params file {file} must map node names to 'ros__parameters', got "
            f"{type(document).__name__}"
        )
    merged: dict[str, object] = {}
    for key, section in document.items():
        applies, specific = section_matches(str(key), node_name, namespace, file)
        if not applies:
            continue
        if not isinstance(section, Mapping) or "ros__parameters" not in section:
            raise GenBacklashError(
                f"params file {file}: section {key!r} must hold a 'ros__parameters' mapping"
            )
        params = section["ros__parameters"]
        if params is None:
            continue
        if not isinstance(params, Mapping):
            raise GenBacklashError(
                f"params file {file}: {key!r} ros__parameters must be a mapping of names"
            )
        for name, value in _flatten("", params):
            if name in STANDARD_NAMES or name.startswith(STANDARD_PREFIXES):
                continue
            if specific or name in SPECS_BY_NAME or is_joint_parameter(name):
                merged[name] = value
    return merged


def load_params_file(
    path: str | Path, node_name: str = NODE_NAME, *, namespace: str | None = None
) -> NodeParameters:
    """:class:`NodeParameters` from a standard ROS 2 params YAML (see :func:`read_params_file`).

    Unknown names in a section naming the node and invalid values are errors naming the
    file. Both transports read a params file with this function (the rclpy node before rcl
    does), so a file means the same to both: the same sections apply under the same
    namespace, a whole number is taken for a double (``publish_rate: 10``), and a value out
    of range stops the node with the same one-line reason.
    """
    return params_from_file(path, read_params_file(path, node_name, namespace=namespace))


def params_from_file(path: str | Path, values: Mapping[str, object]) -> NodeParameters:
    try:
        return NodeParameters.from_mapping(values)
    except GenBacklashError as err:
        raise GenBacklashError(f"params file {Path(path)}: {err}") from err
