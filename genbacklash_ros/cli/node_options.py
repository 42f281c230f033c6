"""The node's parameters on the command line: ``--params-file``, ``--param NAME=VALUE`` and
``--list-params`` for ``replay``, ``identify`` and ``diagnose``, checked against what each
command uses.
"""

from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Collection, Sequence
from pathlib import Path
from typing import Any, NamedTuple

from genbacklash_core import GenBacklashError
from genbacklash_ros.cli.bag_input import is_bag
from genbacklash_ros.node.parameters import (
    PARAMETER_SPECS,
    NodeParameters,
    command_line_parameters,
    parameter_table,
    parse_param_overrides,
)

__all__ = [
    "BATCH_PARAMETERS",
    "SET_BY_REPLAY",
    "CommandParameters",
    "add_node_parameter_options",
    "batch_parameters",
    "node_parameters",
]

# what identify and diagnose use of the node's parameters (the rest is validated, then ignored)
BATCH_PARAMETERS = ("model", "degree", "na", "nb")
# ... and the rule for which samples are rows (genbacklash_core.settling), on bags and on
# a CSV with t (the same rule: genbacklash_ros.node.sample_rule.select_rows)
_ROW_PARAMETERS = ("settle_time", "servo_model", "servo_dead_time", "servo_time_constant")
_BAG_PARAMETERS = ("joint", "command_index", "gear_input", "motor_joint")
# set by the replay itself (genbacklash_ros.bags.replay): the bag's message types, the recorded
# command, no checkpoint
SET_BY_REPLAY = (
    "command_type",
    "encoder_type",
    "motor_encoder_type",
    "compensation_in_loop",
    "checkpoint_file",
)


def batch_parameters(data: str | Path) -> tuple[str, ...]:
    """The node parameters ``identify`` / ``diagnose`` use for ``data`` (a CSV or a bag)."""
    return BATCH_PARAMETERS + _ROW_PARAMETERS + (_BAG_PARAMETERS if is_bag(data) else ())


class _ListParams(argparse.Action):
    """``--list-params``: print the parameter table and exit 0 (like ``--help``)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        kwargs.update(nargs=0, default=argparse.SUPPRESS)
        super().__init__(option_strings, argparse.SUPPRESS, **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: Any,
        option_string: str | None = None,
    ) -> None:
        try:
            print(parameter_table(), flush=True)
        except BrokenPipeError:  # `--list-params | head`: stop quietly, as main() does
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            parser.exit(141)
        parser.exit(0)


def add_node_parameter_options(
    parser: argparse.ArgumentParser, *, used: str, params_file: bool = True
) -> None:
    """``[--params-file FILE] --param NAME=VALUE ... --list-params``; ``used`` says (for the
    help) which parameters the command uses."""
    if params_file:
        parser.add_argument(
            "--params-file",
            metavar="FILE",
            help="the node's ROS 2 parameters YAML (backlash_identifier or /** section), "
            "validated as by 'genbacklash node'; options and --param override it",
        )
    parser.add_argument(
        "--param",
        action="append",
        default=[],
        metavar="NAME=VALUE",
        help="set a node parameter, repeatable, e.g. --param degree=2 --param "
        "method=recursive; VALUE is read as in a params file (2, recursive, false, 0.3, .inf) "
        "and validated the same way; it overrides --params-file, and an option for the same "
        f"parameter must agree with it. {used} --list-params prints every parameter",
    )
    parser.add_argument(
        "--list-params",
        action=_ListParams,
        help="print the node's parameters (type, default, range, unit, meaning) and exit",
    )


class CommandParameters(NamedTuple):
    """The node parameters of one command line (see :func:`node_parameters`)."""

    params: NodeParameters
    given: dict[str, object]
    overrides: dict[str, object]


def node_parameters(args: argparse.Namespace, used: Collection[str]) -> CommandParameters:
    """Defaults < ``--params-file`` < ``--param`` (validated as a params file is), checked
    against the command's options of the same names (``--degree`` ...: they must agree with
    ``--param``).

    Parameters set (by the file or ``--param``) to other than their defaults that the command
    does not use (not in ``used``) are named in one note on stderr.
    """
    overrides = parse_param_overrides(args.param)
    options = {s.name: getattr(args, s.name, None) for s in PARAMETER_SPECS}
    params, given = command_line_parameters(args.params_file, overrides, options)
    # the command's own options (--degree, --na, --nb, --joint, --command-index ...) take
    # the node parameters' ranges: the same check for every command, before any work
    for name, value in options.items():
        if value is None:
            continue
        try:
            params.replace(**{name: value})
        except GenBacklashError as err:
            raise GenBacklashError(f"--{name.replace('_', '-')} {value}: {err}") from err
    defaults = {s.name: s.default for s in PARAMETER_SPECS}
    unused = [
        name
        for name, value in given.items()
        if name not in used and (name not in defaults or value != defaults[name])
    ]
    if unused:
        print(
            f"genbacklash {args.command}: note: {', '.join(unused)} not used by "
            f"{args.command} (validated, ignored)",
            file=sys.stderr,
        )
    return CommandParameters(params, given, overrides)
