"""The node's parameters: one table of specifications, a validated frozen record, params YAML.

:data:`PARAMETER_SPECS` lists every parameter of the ``backlash_identifier`` node with its
type, default, description, unit and allowed range or choices: the rclpy node turns it into
``ParameterDescriptor`` s, the DDS transport and replay read the same values from a standard
ROS 2 parameters YAML (:func:`load_params_file`), and docs/node.md renders it as the reference
(:func:`parameter_table`). :class:`NodeParameters` holds one validated set;
:meth:`NodeParameters.replace` is what a set-parameters callback calls (the new set, or a
:class:`~genbacklash_core.GenBacklashError` whose message is the reason to reject).

Examples
--------
>>> params = NodeParameters.from_mapping({"degree": 2, "method": "recursive"})
>>> params.degree, params.method, params.window
(2, 'recursive', 1500)
>>> params.replace(degree=12)
Traceback (most recent call last):
...
genbacklash_core.errors.GenBacklashError: parameter 'degree' must lie in [1, 9], got 12
"""

from __future__ import annotations

from .command_line import command_line_parameters, parse_param_overrides
from .params_file import load_params_file, read_params_file
from .ros_arguments import RosArguments, parse_ros_arguments
from .specs import (
    JOINT_KEYS,
    NODE_NAME,
    PAIRS,
    PARAMETER_SPECS,
    ParameterSpec,
    is_joint_parameter,
    parameter_table,
)
from .values import NodeParameters, resolve_requested

__all__ = [
    "JOINT_KEYS",
    "NODE_NAME",
    "PAIRS",
    "PARAMETER_SPECS",
    "NodeParameters",
    "ParameterSpec",
    "RosArguments",
    "command_line_parameters",
    "is_joint_parameter",
    "load_params_file",
    "parameter_table",
    "parse_param_overrides",
    "parse_ros_arguments",
    "read_params_file",
    "resolve_requested",
]
