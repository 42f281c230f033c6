"""Node parameters on the command line: ``--param NAME=VALUE`` and ``--params-file`` on
``replay``, ``identify`` and ``diagnose`` (issue 12, item 5)."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import pytest

from genbacklash_core import GenBacklashError, paper_example
from genbacklash_core.diagnose import synthetic_case
from genbacklash_ros.bags.csvio import Series, write_series_csv
from genbacklash_ros.cli.main import EXIT_BAD_INPUT, EXIT_NOT_CONVERGED, EXIT_OK, main
from genbacklash_ros.node.parameters import (
    PARAMETER_SPECS,
    NodeParameters,
    ParameterSpec,
    command_line_parameters,
    parameter_table,
    parse_param_overrides,
)

ROOT = Path(__file__).resolve().parents[3]
EXAMPLE1_BAG = ROOT / "bags" / "example1"
TOPICS = ["--command", "/command", "--encoder", "/encoder"]
COMMANDS = ("replay", "identify", "diagnose")


def _csv(tmp_path: Path) -> Path:
    data = paper_example(1).generate(3)
    path = tmp_path / "ex1.csv"
    write_series_csv(path, Series(u=data.u, y=data.y))
    return path


def _params_file(tmp_path: Path, body: str, name: str = "params.yaml") -> Path:
    path = tmp_path / name
    lines = "".join(f"    {line}\n" for line in body.splitlines())
    path.write_text(f"backlash_identifier:\n  ros__parameters:\n{lines}", encoding="utf-8")
    return path


def _argv(command: str, tmp_path: Path, *extra: str) -> list[str]:
    """A command line of ``command`` whose data need not exist: parameters fail first."""
    if command == "replay":
        return ["replay", str(tmp_path / "no.mcap"), *TOPICS, "-o", str(tmp_path / "o"), *extra]
    return [command, str(tmp_path / "no.csv"), *extra]


def _error(capsys: pytest.CaptureFixture[str], command: str) -> str:
    """The one-line error of the last run, without the ``genbacklash CMD: error:`` prefix."""
    err = capsys.readouterr().err
    assert "Traceback" not in err
    assert err.count("\n") == 1, err
    prefix = f"genbacklash {command}: error: "
    assert err.startswith(prefix), err
    return err[len(prefix) :].rstrip("\n")


def _identify(
    capsys: pytest.CaptureFixture[str], data: Path, *extra: str
) -> tuple[dict[str, object], str]:
    code = main(["identify", str(data), "--json", "--max-iterations", "10", *extra])
    captured = capsys.readouterr()
    assert code in (EXIT_OK, EXIT_NOT_CONVERGED), captured.err
    result: dict[str, object] = json.loads(captured.out)
    return result, captured.err


def _degree(result: dict[str, object]) -> int:
    backlash = result["backlash"]
    assert isinstance(backlash, dict)
    return len(backlash["m_left"])


# --------------------------------------------------------------------------- parsing


def test_values_are_read_as_yaml_scalars() -> None:
    values = parse_param_overrides(
        [
            "degree=2",
            "method=recursive",
            "compensate=false",
            "gate_low=0.3",
            "u_max=.inf",
            "joint=",
            "checkpoint_file=/tmp/a=b.json",
            " window = 20000",
        ]
    )
    assert values == {
        "degree": 2,
        "method": "recursive",
        "compensate": False,
        "gate_low": 0.3,
        "u_max": math.inf,
        "joint": "",
        "checkpoint_file": "/tmp/a=b.json",
        "window": 20000,
    }
    assert isinstance(values["degree"], int) and values["compensate"] is False


def test_same_name_twice() -> None:
    assert parse_param_overrides(["degree=2", "degree=2"]) == {"degree": 2}
    with pytest.raises(GenBacklashError, match=r"--param degree is given twice .*\(2 and 3\)"):
        parse_param_overrides(["degree=2", "degree=3"])
    with pytest.raises(GenBacklashError, match="given twice"):
        parse_param_overrides(["compensate=true", "compensate=1"])  # True == 1, not the same


def test_command_line_parameters_precedence(tmp_path: Path) -> None:
    file = _params_file(tmp_path, "degree: 2\nmethod: recursive\nwindow: 300")
    params, given = command_line_parameters(file, {"degree": 4, "gate_low": 0.1})
    assert (params.degree, params.method, params.window, params.gate_low) == (
        4,
        "recursive",
        300,
        0.1,
    )
    assert given == {"degree": 4, "method": "recursive", "window": 300, "gate_low": 0.1}
    defaults, none = command_line_parameters(None, {})
    assert defaults == NodeParameters() and none == {}
    # an option agrees with --param: fine (int and float of one number are the same value)
    command_line_parameters(None, {"degree": 2, "forgetting": 1}, {"degree": 2, "forgetting": 1.0})
    # an option without --param: no check here (the command applies it over the file)
    command_line_parameters(file, {}, {"degree": 7})
    with pytest.raises(GenBacklashError, match=r"--degree 3 and --param degree=2 disagree"):
        command_line_parameters(file, {"degree": 2}, {"degree": 3})


# --------------------------------------------------------------------------- round trips


def test_replay_param_reaches_the_pipeline_and_overrides_the_params_file(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """bags/example1 with a cascade params file and --param model=backlash, degree=2."""
    file = _params_file(tmp_path, "model: cascade\ndegree: 3\nmethod: windowed")
    argv = ["replay", str(EXAMPLE1_BAG), *TOPICS, "-o", str(tmp_path / "out"), "--json"]
    argv += ["--no-progress", "--params-file", str(file), "--param", "model=backlash"]
    argv += ["--param", "degree=2", "--param", "checkpoint_file=never.json"]
    assert main(argv) == EXIT_OK
    captured = capsys.readouterr()
    assert list(json.loads(captured.out)["parameters"]) == [
        "m_left_1", "m_left_2", "c_left", "m_right_1", "m_right_2", "c_right"
    ]  # fmt: skip
    # a replay writes no checkpoint: the parameter is validated, then ignored with a note
    assert "note: checkpoint_file not used by replay" in captured.err
    assert not (tmp_path / "never.json").exists() and not Path("never.json").exists()


def test_identify_param_degree_on_a_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    result, err = _identify(capsys, _csv(tmp_path), "--param", "degree=2")
    assert _degree(result) == 2 and result["model"] == "backlash"
    assert err == ""


def test_identify_precedence(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """defaults < params file < (--degree and --param, which must agree)."""
    data = _csv(tmp_path)
    file = str(_params_file(tmp_path, "degree: 2"))
    assert _degree(_identify(capsys, data)[0]) == 3
    assert _degree(_identify(capsys, data, "--params-file", file)[0]) == 2
    assert _degree(_identify(capsys, data, "--params-file", file, "--param", "degree=1")[0]) == 1
    assert _degree(_identify(capsys, data, "--params-file", file, "--degree", "1")[0]) == 1
    agreed = ("--params-file", file, "--degree", "1", "--param", "degree=1")
    assert _degree(_identify(capsys, data, *agreed)[0]) == 1


def test_identify_uses_the_bag_parameters(capsys: pytest.CaptureFixture[str]) -> None:
    """joint and command_index from --param reach the bag reader."""
    argv = ["identify", str(EXAMPLE1_BAG), *TOPICS, "--json", "--max-iterations", "5"]
    assert main([*argv, "--param", "command_index=3"]) == EXIT_BAD_INPUT
    assert "command index 3 is beyond the Float64MultiArray" in _error(capsys, "identify")
    assert main([*argv, "--param", "joint=elbow"]) == EXIT_BAD_INPUT
    assert "joint 'elbow' is not in the encoder JointState" in _error(capsys, "identify")
    assert main([*argv, "--param", "joint=drive_joint"]) in (EXIT_OK, EXIT_NOT_CONVERGED)
    assert capsys.readouterr().err == ""


def test_diagnose_param_sets_the_starting_structure(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    case = synthetic_case([], 5, 800)
    data = tmp_path / "clean.csv"
    write_series_csv(data, Series(case.u, case.y))
    assert main(["diagnose", str(data), "--json", "--param", "degree=2"]) == EXIT_OK
    assert len(json.loads(capsys.readouterr().out)["model"]["backlash"]["m_left"]) == 2
    # a params file's structure gives way to --start (an option over the file) ...
    file = str(_params_file(tmp_path, "degree: 2"))
    argv = ["diagnose", str(data), "--json", "--params-file", file, "--start", "degree=1"]
    assert main(argv) == EXIT_OK
    assert len(json.loads(capsys.readouterr().out)["model"]["backlash"]["m_left"]) == 1
    # ... but --start and a structure --param are one setting given twice
    assert main(["diagnose", str(data), "--start", "degree=1", "--param", "na=1"]) == 2
    assert "--start and --param na both set the starting model" in _error(capsys, "diagnose")


# --------------------------------------------------------------------------- validation


def _bad_value(spec: ParameterSpec) -> str:
    """A value of ``spec`` that its range or type rejects, as params-file text."""
    if spec.type == "bool":
        return "maybe"
    if spec.type == "string":
        return "not_one_of_them" if spec.choices else "5"
    if spec.max is not None and not math.isinf(spec.max):
        return str(int(spec.max) + 1) if spec.type == "integer" else repr(float(spec.max) + 1)
    if spec.min is not None and not math.isinf(spec.min):
        return str(int(spec.min) - 1) if spec.type == "integer" else repr(float(spec.min) - 1)
    return "abc"


@pytest.mark.parametrize("spec", PARAMETER_SPECS, ids=[s.name for s in PARAMETER_SPECS])
def test_param_and_params_file_give_the_same_error(
    spec: ParameterSpec, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    value = _bad_value(spec)
    file = _params_file(tmp_path, f"{spec.name}: {value}")
    assert main(_argv("identify", tmp_path, "--params-file", str(file))) == EXIT_BAD_INPUT
    via_file = _error(capsys, "identify")
    assert main(_argv("identify", tmp_path, "--param", f"{spec.name}={value}")) == 2
    via_param = _error(capsys, "identify")
    assert via_file.startswith(f"params file {file}: parameter {spec.name!r} ")
    assert via_param.startswith("--param: ")
    assert via_param.removeprefix("--param: ") == via_file.removeprefix(f"params file {file}: ")


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_validates_the_same_way(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(_argv(command, tmp_path, "--param", "degree=12")) == EXIT_BAD_INPUT
    assert _error(capsys, command) == "--param: parameter 'degree' must lie in [1, 9], got 12"
    # a cross-check between a file value and a --param value
    file = _params_file(tmp_path, "gate_high: 0.4")
    argv = _argv(command, tmp_path, "--params-file", str(file), "--param", "gate_low=0.5")
    assert main(argv) == EXIT_BAD_INPUT
    assert _error(capsys, command) == (
        "--param: parameter 'gate_low' (0.5) must not exceed 'gate_high' (0.4)"
    )


@pytest.mark.parametrize("command", COMMANDS)
def test_unknown_name_lists_close_matches(
    command: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(_argv(command, tmp_path, "--param", "degre=2")) == EXIT_BAD_INPUT
    assert _error(capsys, command) == (
        "--param: unknown parameter 'degre' (close matches: degree); --list-params prints all names"
    )
    assert main(_argv(command, tmp_path, "--param", "gate=0.3")) == EXIT_BAD_INPUT
    assert "(close matches: gate_low, gate_high)" in _error(capsys, command)
    assert main(_argv(command, tmp_path, "--param", "zzzz=1")) == EXIT_BAD_INPUT
    assert "unknown parameter 'zzzz' (no close match)" in _error(capsys, command)


@pytest.mark.parametrize("item", ["degree", "=2", " =2", ""])
def test_malformed_param(item: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(_argv("replay", tmp_path, "--param", item)) == EXIT_BAD_INPUT
    assert _error(capsys, "replay") == (
        f"--param takes NAME=VALUE (e.g. --param degree=2), got {item!r}"
    )


def test_value_that_is_not_yaml(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(_argv("identify", tmp_path, "--param", "joint=[")) == EXIT_BAD_INPUT
    assert _error(capsys, "identify").startswith("--param joint=[: the value is not valid YAML")


@pytest.mark.parametrize(
    ("command", "option"),
    [
        ("replay", ["--degree", "3"]),
        ("replay", ["--method", "windowed"]),
        ("identify", ["--model", "cascade"]),
        ("identify", ["--joint", "knee"]),
        ("diagnose", ["--command-index", "1"]),
    ],
)
def test_option_and_param_must_agree(
    command: str, option: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    flag = option[0]
    name = flag.removeprefix("--").replace("-", "_")
    other = {"degree": "2", "method": "recursive", "model": "backlash", "joint": "hip"}
    param = f"{name}={other.get(name, '0')}"
    assert main(_argv(command, tmp_path, *option, "--param", param)) == EXIT_BAD_INPUT
    message = _error(capsys, command)
    assert message.startswith(f"{flag} ") and f"and --param {param}" in message
    assert message.endswith(f"disagree; give {name} once")


# --------------------------------------------------------------------------- notes and help


def test_unused_parameters_get_one_note(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _csv(tmp_path)
    extra = ["--param", "window=20000", "--param", "compensate=false", "--param", "joint=knee"]
    result, err = _identify(capsys, data, "--param", "degree=2", *extra)
    assert _degree(result) == 2
    assert err == (
        "genbacklash identify: note: window, compensate, joint not used by identify "
        "(validated, ignored)\n"
    )
    # the node's params file, every parameter at its default: no note, no change
    result, err = _identify(capsys, data, "--params-file", str(ROOT / "config" / "params.yaml"))
    assert _degree(result) == 3 and err == ""


@pytest.mark.parametrize("command", COMMANDS)
def test_list_params_prints_the_table(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main([command, "--list-params"])  # before the required arguments are checked
    assert exit_info.value.code == 0
    assert capsys.readouterr().out == parameter_table() + "\n"


@pytest.mark.parametrize("command", COMMANDS)
def test_help_mentions_param(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main([command, "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--param NAME=VALUE" in text and "--param degree=2" in text
    assert "--list-params" in text and "--params-file FILE" in text


def test_console_script(tmp_path: Path) -> None:
    """The installed ``genbacklash``: a --param round trip and an error, in real processes."""
    script = Path(sys.executable).with_name("genbacklash")
    if not script.exists():
        pytest.skip(f"no console script next to {sys.executable}")
    data = _csv(tmp_path)
    argv = [str(script), "identify", str(data), "--json", "--param", "degree=2"]
    proc = subprocess.run(argv, capture_output=True, text=True, timeout=120, check=False)
    assert proc.returncode in (EXIT_OK, EXIT_NOT_CONVERGED), proc.stderr
    assert len(json.loads(proc.stdout)["backlash"]["m_left"]) == 2
    argv = [str(script), "replay", str(EXAMPLE1_BAG), *TOPICS, "-o", str(tmp_path / "o")]
    proc = subprocess.run(
        [*argv, "--param", "method=recursiv"],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == EXIT_BAD_INPUT
    assert proc.stderr == (
        "genbacklash replay: error: --param: parameter 'method' must be one of 'windowed', "
        "'recursive', got 'recursiv'\n"
    )
    assert not (tmp_path / "o").exists()
