"""Node parameters: specs, validation with reasons, replace, params YAML."""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import pytest

from genbacklash_core import (
    GenBacklashError,
    RecursiveIdentifier,
    Structure,
    WindowedIdentifier,
    WindowedSettings,
)
from genbacklash_ros.node.parameters import (
    PARAMETER_SPECS,
    NodeParameters,
    load_params_file,
    parameter_table,
    parse_ros_arguments,
    read_params_file,
    resolve_requested,
)

ROOT = Path(__file__).resolve().parents[3]


def test_specs_match_the_dataclass_fields_and_defaults() -> None:
    fields = {f.name: f.default for f in dataclasses.fields(NodeParameters)}
    assert [s.name for s in PARAMETER_SPECS] == list(fields)
    for spec in PARAMETER_SPECS:
        assert spec.default == fields[spec.name], spec.name
        assert spec.description.endswith("."), spec.name
        spec.check(spec.default)  # every default is allowed
    assert NodeParameters().window == WindowedSettings().window


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"degree": 0}, r"parameter 'degree' must lie in \[1, 9\], got 0"),
        ({"degree": 10}, r"parameter 'degree' must lie in \[1, 9\], got 10"),
        ({"degree": 2.0}, "parameter 'degree' must be a whole number, got 2.0"),
        ({"degree": True}, "parameter 'degree' must be a whole number, got True"),
        ({"model": "linear"}, "parameter 'model' must be one of 'backlash', 'cascade'"),
        ({"method": "rls"}, "parameter 'method' must be one of 'windowed', 'recursive'"),
        ({"window": 5}, r"parameter 'window' must lie in \[20, 1e\+07\], got 5"),
        ({"forgetting": 1.5}, r"parameter 'forgetting' must lie in \[0.5, 1\], got 1.5"),
        ({"forgetting": math.nan}, "parameter 'forgetting' must be a number, got NaN"),
        ({"forgetting": "0.9"}, "parameter 'forgetting' must be a number, got '0.9'"),
        ({"na": 0}, r"parameter 'na' must lie in \[1, 10\]"),
        ({"nb": -1}, r"parameter 'nb' must lie in \[0, 10\]"),
        ({"command_index": -1}, r"parameter 'command_index' must lie in \[0, 65535\]"),
        ({"command_type": "string"}, "parameter 'command_type' must be one of 'float64'"),
        ({"encoder_type": "imu"}, "parameter 'encoder_type' must be one of 'joint_state'"),
        ({"compensate": 1}, "parameter 'compensate' must be true or false, got 1"),
        ({"joint": 3}, "parameter 'joint' must be a string, got 3"),
        ({"u_min": 1.0, "u_max": 1.0}, r"parameter 'u_min' \(1\) must be below 'u_max' \(1\)"),
        ({"max_rate": 0.0}, r"parameter 'max_rate' must lie in \[1e-12, inf\], got 0.0"),
        ({"gate_low": 0.6}, r"parameter 'gate_low' \(0.6\) must not exceed 'gate_high' \(0.5\)"),
        ({"gate_high": 1.5}, r"parameter 'gate_high' must lie in \[0, 1\]"),
        ({"checkpoint_period": 0.0}, r"parameter 'checkpoint_period' must lie in \[0.1, 86400\]"),
        ({"publish_rate": 0.0}, r"parameter 'publish_rate' must lie in \[0.01, 1000\]"),
        ({"sample_period": -0.001}, r"parameter 'sample_period' must lie in \[0, 10\]"),
        ({"stamp_source": "bag"}, "parameter 'stamp_source' must be one of 'header', 'receive'"),
    ],
)
def test_invalid_values_are_rejected_with_the_reason(
    changes: dict[str, object], match: str
) -> None:
    with pytest.raises(GenBacklashError, match=match):
        NodeParameters.from_mapping(changes)
    with pytest.raises(GenBacklashError, match=match):
        NodeParameters().replace(**changes)


def test_whole_numbers_are_taken_for_doubles() -> None:
    params = NodeParameters.from_mapping({"forgetting": 1, "u_max": 2})
    assert params.forgetting == 1.0 and isinstance(params.forgetting, float)
    assert params.u_max == 2.0 and isinstance(params.u_max, float)


def test_unknown_names_are_listed() -> None:
    with pytest.raises(GenBacklashError, match=r"unknown parameter\(s\) 'degre', 'windw'"):
        NodeParameters.from_mapping({"degre": 3, "windw": 10})
    with pytest.raises(GenBacklashError, match="unknown parameter"):
        NodeParameters().replace(bogus=1)


def test_replace_validates_and_leaves_the_original() -> None:
    base = NodeParameters()
    new = base.replace(degree=2, compensate=False)
    assert (new.degree, new.compensate) == (2, False)
    assert (base.degree, base.compensate) == (3, True)
    assert base.restart_needed(new)  # degree restarts identification
    assert not base.restart_needed(base.replace(compensate=False, u_max=3.0))
    assert NodeParameters.from_mapping(new.to_mapping()) == new


def test_identifier_and_structure() -> None:
    assert NodeParameters().structure() == Structure(3)
    assert NodeParameters(model="cascade", na=2, nb=1).structure() == Structure(3, 2, 1)
    windowed = NodeParameters(window=300).make_identifier()
    assert isinstance(windowed, WindowedIdentifier)
    assert windowed.settings.window == 300 and windowed.settings.nonfinite == "drop"
    recursive = NodeParameters(method="recursive", forgetting=0.999).make_identifier(sign=-1.0)
    assert isinstance(recursive, RecursiveIdentifier)
    assert recursive.settings.forgetting == 0.999 and recursive.structure.sign == -1.0
    options = NodeParameters(u_min=-1.0, u_max=1.0, max_rate=0.1).compensator_options()
    assert (options.u_min, options.u_max, options.max_rate) == (-1.0, 1.0, 0.1)


def test_periods_in_nanoseconds() -> None:
    params = NodeParameters(sample_period=0.001, publish_rate=3.0, checkpoint_period=2.5)
    assert params.sample_period_ns == 1_000_000
    assert params.publish_period_ns == 333_333_333
    assert params.checkpoint_period_ns == 2_500_000_000


def test_parameter_table_lists_every_parameter() -> None:
    table = parameter_table()
    for spec in PARAMETER_SPECS:
        assert f"| `{spec.name}` |" in table
    assert "| `degree` | integer | 3 | [1, 9] |" in table


# --------------------------------------------------------------------------- params YAML


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(text, encoding="utf-8")
    return path


def test_node_section_is_loaded(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """
backlash_identifier:
  ros__parameters:
    degree: 2
    method: recursive
    u_min: -.inf
    u_max: 1.5
    joint: knee
""",
    )
    params = load_params_file(path)
    assert (params.degree, params.method, params.joint) == (2, "recursive", "knee")
    assert params.u_min == -math.inf and params.u_max == 1.5


def test_wildcard_and_namespaced_sections_merge_in_file_order(tmp_path: Path) -> None:
    path = write(
        tmp_path,
        """
/**:
  ros__parameters:
    use_sim_time: true
    degree: 4
    publish_rate: 5.0
    some_other_nodes_parameter: 1
/robot/backlash_identifier:
  ros__parameters:
    degree: 2
    qos_overrides:
      /encoder:
        subscription:
          depth: 10
other_node:
  ros__parameters:
    degree: 9
    whatever: 1
""",
    )
    raw = read_params_file(path)
    assert raw == {"degree": 2, "publish_rate": 5.0}
    params = load_params_file(path)
    assert (params.degree, params.publish_rate) == (2, 5.0)
    other = read_params_file(path, node_name="other_node")
    assert other == {"degree": 9, "publish_rate": 5.0, "whatever": 1}


def test_unknown_name_in_the_nodes_own_section_is_an_error(tmp_path: Path) -> None:
    path = write(tmp_path, "backlash_identifier:\n  ros__parameters:\n    degre: 2\n")
    with pytest.raises(GenBacklashError, match=r"params\.yaml: unknown parameter\(s\) 'degre'"):
        load_params_file(path)
    with pytest.raises(GenBacklashError) as info:
        load_params_file(path)
    # the close matches, not every name of the node (issue 24)
    assert (
        str(info.value)
        == f"params file {path}: unknown parameter(s) 'degre' (close matches: degree)"
    )


def test_unknown_names_each_get_their_close_matches() -> None:
    with pytest.raises(GenBacklashError) as info:
        NodeParameters.from_mapping({"degre": 3, "windw": 10, "zzzz": 1})
    assert str(info.value) == (
        "unknown parameter(s) 'degre', 'windw', 'zzzz': 'degre': close matches: degree; "
        "'windw': close matches: window; 'zzzz': no close match"
    )


@pytest.mark.parametrize(
    ("namespace", "rule"),
    [("", "degre:=2"), ("/arm", "degre:=2"), ("", "backlash_identifier:degre:=2")],
)
def test_an_unknown_ros_args_parameter_is_refused_with_the_close_matches(
    namespace: str, rule: str
) -> None:
    """rcl takes any `-p` name; the node would ignore a typo (issue 24)."""
    ros = parse_ros_arguments(["n", "--ros-args", "-r", f"__ns:={namespace}", "--param", rule])
    with pytest.raises(GenBacklashError) as info:
        ros.check_parameter_names()
    assert str(info.value) == "-p: unknown parameter 'degre' (close matches: degree)"


def test_ros_args_parameters_of_other_nodes_and_standard_ones_pass() -> None:
    argv = ["n", "--ros-args", "-p", "other_node:degre:=2", "-p", "use_sim_time:=true"]
    argv += ["-p", "qos_overrides./command.subscription.depth:=5", "-p", "degree:=2"]
    argv += ["-r", "__ns:=/arm", "-p", "backlash_identifier:degre:=2", "--", "-p", "degre:=1"]
    ros = parse_ros_arguments(argv)  # (rcl applies `-p NODE:...` as a params file's `NODE:`)
    ros.check_parameter_names()
    assert ros.node_parameters() == {
        "use_sim_time": "true",
        "qos_overrides./command.subscription.depth": "5",
        "degree": "2",
    }


def test_invalid_value_in_a_file_names_the_file(tmp_path: Path) -> None:
    path = write(tmp_path, "backlash_identifier:\n  ros__parameters:\n    degree: 12\n")
    with pytest.raises(GenBacklashError, match=r"params\.yaml: parameter 'degree' must lie"):
        load_params_file(path)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("backlash_identifier: [1, 2", r"is not valid YAML \(line"),
        ("- 1\n- 2\n", "must map node names to 'ros__parameters', got list"),
        ("backlash_identifier:\n  degree: 2\n", "must hold a 'ros__parameters' mapping"),
        ("backlash_identifier:\n  ros__parameters: 3\n", "ros__parameters must be a mapping"),
    ],
)
def test_malformed_files_are_reported(tmp_path: Path, text: str, match: str) -> None:
    with pytest.raises(GenBacklashError, match=match):
        load_params_file(write(tmp_path, text))


def test_a_file_that_is_not_yaml_is_reported_on_one_line(tmp_path: Path) -> None:
    with pytest.raises(GenBacklashError) as caught:
        load_params_file(write(tmp_path, "x: [\n"))
    message = str(caught.value)
    assert "\n" not in message, message  # the parser's own message quotes the line below it
    assert "is not valid YAML (line 2): expected the node content" in message


def test_missing_and_empty_files(tmp_path: Path) -> None:
    with pytest.raises(GenBacklashError, match="cannot read params file"):
        load_params_file(tmp_path / "absent.yaml")
    assert load_params_file(write(tmp_path, "")) == NodeParameters()
    assert load_params_file(write(tmp_path, "other:\n  ros__parameters: {degree: 1}\n")) == (
        NodeParameters()
    )


# Which top-level keys rcl (ROS 2 Jazzy, rcl 9.2.0) applies to backlash_identifier in the
# namespaces /, /arm and /a/b: measured with rclpy on this machine, and checked again by
# test_sections_apply_as_rcl_applies_them where rclpy imports.
RCL_SECTIONS: dict[str, tuple[bool, bool, bool]] = {
    "/**": (True, True, True),
    "**": (True, True, True),
    "/**/backlash_identifier": (True, True, True),
    "/**/*": (True, True, True),
    "backlash_identifier": (True, False, False),
    "/backlash_identifier": (True, False, False),
    "*": (True, False, False),
    "/*": (True, False, False),
    "arm/backlash_identifier": (False, True, False),
    "/arm/backlash_identifier": (False, True, False),
    "/*/backlash_identifier": (False, True, False),
    "*/backlash_identifier": (False, True, False),
    "/arm/*": (False, True, False),
    "/arm/**": (False, True, False),
    "arm/**": (False, True, False),
    "/**/arm/backlash_identifier": (False, True, False),
    "/x/backlash_identifier": (False, False, False),
    "/arm/*/backlash_identifier": (False, False, False),
}
NAMESPACES = ("", "/arm", "/a/b")


def _one_section(tmp_path: Path, key: str) -> Path:
    return write(tmp_path, f'"{key}":\n  ros__parameters:\n    degree: 2\n')


@pytest.mark.parametrize("key", sorted(RCL_SECTIONS))
def test_sections_apply_under_a_namespace_as_in_rcl(tmp_path: Path, key: str) -> None:
    path = _one_section(tmp_path, key)
    for namespace, applies in zip(NAMESPACES, RCL_SECTIONS[key], strict=True):
        got = load_params_file(path, namespace=namespace).degree == 2
        assert got == applies, (key, namespace)
    # without a namespace (replay, identify, diagnose): a section naming the node, or a
    # wildcard in its place, applies
    last = key.rsplit("/", 1)[-1]
    assert (load_params_file(path).degree == 2) == (last in ("backlash_identifier", "*", "**"))


def test_the_config_file_applies_under_a_namespace() -> None:
    """config/params.yaml was keyed `backlash_identifier:`, which rcl reads as
    `/backlash_identifier`: under `namespace:=arm` the node ran on its defaults silently."""
    config = ROOT / "config" / "params.yaml"
    for namespace in NAMESPACES:
        values = read_params_file(config, namespace=namespace)
        assert set(values) == {s.name for s in PARAMETER_SPECS}, namespace


def test_section_keys_rcl_refuses_are_refused(tmp_path: Path) -> None:
    path = write(tmp_path, "backlash_*:\n  ros__parameters:\n    degree: 2\n")
    with pytest.raises(GenBacklashError, match="'backlash_\\*' is not a node name ROS 2"):
        load_params_file(path)


def test_sections_apply_as_rcl_applies_them(tmp_path: Path) -> None:
    """The same keys through the real rcl: what rclpy declares equals what the reader says."""
    from tests.ros.transports._ros2 import domain_id, rclpy_missing

    if reason := rclpy_missing():
        pytest.skip(reason)
    import rclpy
    from rclpy.node import Node

    for key in RCL_SECTIONS:
        path = _one_section(tmp_path, key)
        for namespace in NAMESPACES:
            args = ["x", "--ros-args", "--params-file", str(path)]
            if namespace:
                args += ["-r", f"__ns:={namespace}"]
            rclpy.init(args=args, domain_id=domain_id())
            try:
                node = Node("backlash_identifier")
                rcl = node.declare_parameter("degree", 3).value == 2
                node.destroy_node()
            finally:
                rclpy.try_shutdown()
            ours = load_params_file(path, namespace=namespace).degree == 2
            assert ours == rcl, (key, namespace)


def test_ros_arguments_name_the_files_and_the_namespace() -> None:
    launch = [
        "/ws/install/genbacklash_ros/lib/genbacklash_ros/backlash_identifier",
        "--ros-args",
        "-r",
        "__node:=identifier",
        "-r",
        "__ns:=/arm",
        "--params-file",
        "/tmp/a.yaml",
        "-r",
        "command:=/arm/command",
        "--log-level",
        "debug",
        "--params-file",
        "/tmp/b.yaml",
    ]
    ros = parse_ros_arguments(launch)
    assert ros.params_files == ("/tmp/a.yaml", "/tmp/b.yaml")
    assert (ros.namespace, ros.node_name) == ("/arm", "identifier")
    assert parse_ros_arguments(["x", "--params-file", "not_ros.yaml"]).params_files == ()
    only_p = parse_ros_arguments(["x", "--ros-args", "-p", "degree:=2"])
    assert dataclasses.replace(only_p, parameters=()) == parse_ros_arguments([])
    assert only_p.parameters == (("", "degree", "2"),)


@pytest.mark.parametrize(
    ("low", "high", "start", "goal"),
    [
        ("gate_low", "gate_high", (0.2, 0.5), (0.7, 0.9)),
        ("gate_low", "gate_high", (0.2, 0.5), (0.05, 0.1)),
        ("u_min", "u_max", (-1.0, 1.0), (2.0, 3.0)),
        ("u_min", "u_max", (-1.0, 1.0), (-3.0, -2.0)),
    ],
)
def test_a_pair_moves_in_either_order(
    low: str, high: str, start: tuple[float, float], goal: tuple[float, float]
) -> None:
    """One parameter per request: the first set leaves the pair inconsistent, the node keeps
    the old pair (and says so) until the second set makes it consistent."""
    now = NodeParameters.from_mapping({low: start[0], high: start[1]})
    for first, second in ((low, high), (high, low)):
        target = dict(zip((low, high), goal, strict=True))
        held: dict[str, object] = {**now.to_mapping(), first: target[first]}
        params, pending = resolve_requested(now, held)
        if pending:  # the pair is inconsistent in between: the old one runs
            assert (getattr(params, low), getattr(params, high)) == start
            assert low in pending[0] and "until the pair is consistent" in pending[0]
        held[second] = target[second]
        params, pending = resolve_requested(params, held)
        assert pending == ()
        assert (getattr(params, low), getattr(params, high)) == goal
    # one of the two orders must pass through an inconsistent pair (else nothing is tested)
    assert any(
        resolve_requested(now, {name: dict(zip((low, high), goal, strict=True))[name]})[1]
        for name in (low, high)
    )


def test_other_values_apply_while_a_pair_is_pending() -> None:
    now = NodeParameters()
    params, pending = resolve_requested(now, {"gate_high": 0.1, "publish_rate": 3.0})
    assert params.publish_rate == 3.0 and params.gate_high == now.gate_high
    assert len(pending) == 1
