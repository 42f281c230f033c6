"""``--param NAME=VALUE`` overrides and the ``--params-file`` of the command line merged into
the node's parameters, each value read as a params file would hold it."""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from pathlib import Path

from genbacklash_core import (
    GenBacklashError,
)

from .params_file import params_from_file, read_params_file
from .specs import SPECS_BY_NAME, is_joint_parameter, is_standard, unknown_name
from .values import NodeParameters


def _yaml_value(item: str, text: str) -> object:
    """``text`` read as the YAML scalar a params file would hold; empty: the empty string."""
    if not text.strip():
        return ""
    import yaml

    try:
        value: object = yaml.safe_load(text)
    except yaml.YAMLError as err:
        problem = getattr(err, "problem", None) or str(err).splitlines()[0]
        raise GenBacklashError(f"--param {item}: the value is not valid YAML ({problem})") from err
    return value


def parse_param_overrides(items: Iterable[str]) -> dict[str, object]:
    """``NAME=VALUE`` items of ``--param`` -> ``{name: value}``, values not yet validated.

    VALUE is read as a YAML scalar, as a params file holds it (``2``, ``recursive``,
    ``false``, ``0.3``, ``.inf``); an empty VALUE is the empty string. Unknown names are an
    error listing the close matches; the standard ``use_sim_time`` / ``qos_overrides.*`` are
    accepted, as in a params file. Giving one name twice with different values is an error.

    >>> parse_param_overrides(["degree=2", "method=recursive", "compensate=false"])
    {'degree': 2, 'method': 'recursive', 'compensate': False}
    >>> parse_param_overrides(["degre=2"])  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: --param: unknown parameter 'degre' (close ...
    """
    values: dict[str, object] = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise GenBacklashError(
                f"--param takes NAME=VALUE (e.g. --param degree=2), got {item!r}"
            )
        if name not in SPECS_BY_NAME and not is_standard(name):
            raise GenBacklashError(unknown_name(name))
        value = _yaml_value(item, text)
        if name in values and (type(values[name]), values[name]) != (type(value), value):
            raise GenBacklashError(
                f"--param {name} is given twice with different values "
                f"({values[name]!r} and {value!r}); give it once"
            )
        values[name] = value
    return values


def _option_name(name: str) -> str:
    return "--" + name.replace("_", "-")


def _as_typed(value: object) -> str:
    """A value as it is written on a command line (``''`` for the empty string)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str) and (not value or value != value.strip()):
        return repr(value)
    return str(value)


def command_line_parameters(
    params_file: str | Path | None,
    overrides: Mapping[str, object],
    options: Mapping[str, object] | None = None,
) -> tuple[NodeParameters, dict[str, object]]:
    """The node parameters a command line asks for, and the names it sets.

    Precedence: defaults < ``params_file`` < ``overrides`` (``--param``, from
    :func:`parse_param_overrides`). ``options`` are a command's own options for parameters of
    the same name (``--degree``, ``--joint``, ...; None: not given): the command applies them
    over the params file itself, and one given both ways must agree with ``--param`` (an error
    otherwise, never a silent choice). The file and the overrides are validated by
    :meth:`NodeParameters.from_mapping`, with the params file's error text (prefixed by the
    file, or by ``--param``).

    Returns
    -------
    params : NodeParameters
        Defaults, updated by the params file, then by ``--param``.
    given : dict
        Name -> value of every parameter the params file or ``--param`` sets (after
        ``--param``; standard ROS ones such as ``use_sim_time`` included, unvalidated).
    """
    file_values = read_params_file(params_file) if params_file else {}
    if params_file:
        _check_joint_values(params_file, file_values)
    node_values = {k: v for k, v in file_values.items() if not is_joint_parameter(k)}
    if params_file:
        params_from_file(params_file, node_values)
    own = {k: v for k, v in overrides.items() if k in SPECS_BY_NAME}
    try:
        params = NodeParameters.from_mapping({**node_values, **own})
    except GenBacklashError as err:
        raise GenBacklashError(f"--param: {err}") from err
    for name, value in (options or {}).items():
        if value is None or name not in own:
            continue
        chosen = getattr(params, name)
        if chosen != value or isinstance(chosen, bool) != isinstance(value, bool):
            raise GenBacklashError(
                f"{_option_name(name)} {_as_typed(value)} and --param "
                f"{name}={_as_typed(chosen)} disagree; give {name} once"
            )
    given: dict[str, object] = {**file_values, **overrides}
    for name in given:
        if name in SPECS_BY_NAME:
            given[name] = getattr(params, name)
    return params, given


def _check_joint_values(path: str | Path, values: Mapping[str, object]) -> None:
    """A node params file's ``joints``, ``command_indices`` and ``<joint>.<name>`` checked as
    the node checks them (the commands take their joints from ``--joint``, not from these)."""
    if not any(is_joint_parameter(k) for k in values):
        return
    from genbacklash_ros.node.joints import JointSet  # (joints imports this module)

    try:
        JointSet.from_mapping(values)
    except GenBacklashError as err:
        raise GenBacklashError(f"params file {Path(path)}: {err}") from err
