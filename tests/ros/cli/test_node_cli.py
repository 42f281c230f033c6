"""``genbacklash node``: options, transport choice, errors before any middleware starts."""

from __future__ import annotations

import argparse
import importlib.util
import signal
from pathlib import Path
from typing import Any

import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.cli import node as node_cli
from genbacklash_ros.cli.main import main


def test_help_explains_transports(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["node", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for text in ("--transport", "--params-file", "--domain-id", "rclpy", "cyclonedds", "auto"):
        assert text in out


def test_dds_without_cyclonedds_names_the_extra(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    real = importlib.util.find_spec

    def find_spec(name: str, *args: Any) -> Any:
        return None if name in ("cyclonedds", "rclpy") else real(name, *args)

    monkeypatch.setattr(importlib.util, "find_spec", find_spec)
    assert main(["node", "--transport", "dds"]) == 2
    assert "pip install genbacklash[dds]" in capsys.readouterr().err
    with pytest.raises(GenBacklashError, match="neither rclpy"):
        node_cli.choose_transport("auto")


def test_bad_params_file_is_reported_before_starting(
    tmp_path: Any, capsys: pytest.CaptureFixture[str]
) -> None:
    pytest.importorskip("cyclonedds")
    bad = tmp_path / "p.yaml"
    bad.write_text("backlash_identifier:\n  ros__parameters:\n    degree: 42\n")
    assert main(["node", "--transport", "dds", "--params-file", str(bad)]) == 2
    assert "degree" in capsys.readouterr().err


def test_remap_syntax() -> None:
    assert node_cli._remaps(["command:=/arm/cmd", "~/estimate:=est"]) == {
        "command": "/arm/cmd",
        "estimate": "est",
    }
    with pytest.raises(GenBacklashError, match="NAME:=TOPIC"):
        node_cli._remaps(["command=/x"])


def test_domain_id_range(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        main(["node", "--domain-id", "300"])
    assert "[0, 232]" in capsys.readouterr().err


def test_dds_node_runs_for_a_moment_and_stops(tmp_path: Any) -> None:
    """In-process: a short --duration run publishes stale diagnostics and exits 0."""
    pytest.importorskip("cyclonedds")
    from genbacklash_ros.node.parameters import NodeParameters
    from genbacklash_ros.transports.dds_node import DdsNode

    node = DdsNode(NodeParameters(), domain_id=231)
    stats = node.spin(1.3)
    assert stats.stale_reports >= 1
    assert stats.published["diagnostics"] >= 1


def test_the_ros2_executable_and_genbacklash_node_start_the_rclpy_node(
    monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """Both entry points import the rclpy transport (they looked for it in the cli package
    after the move to subpackages: ModuleNotFoundError under `ros2 launch`). An invalid
    `-p` stops the node with its one line, after the import."""
    from tests.ros.transports._ros2 import rclpy_missing

    if reason := rclpy_missing():
        pytest.skip(reason)
    argv = ["backlash_identifier", "--ros-args", "-p", "degree:=12"]
    monkeypatch.setattr("sys.argv", argv)
    # the entry point leaves SIGINT and SIGTERM ignored for its process's exit (stop_signals):
    # here that process is pytest's, whose later subprocesses would inherit the ignoring
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        assert node_cli.ros2_main() == 2
        assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN  # as a process's own exit
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    line = "parameter 'degree' must lie in [1, 9], got 12"
    assert capfd.readouterr().err.strip() == f"backlash_identifier: error: {line}"
    bad = tmp_path / "p.yaml"
    bad.write_text("/**/backlash_identifier:\n  ros__parameters:\n    window: 5\n")
    args = argparse.Namespace(params_file=str(bad), namespace="arm", remap=[], domain_id=None)
    assert node_cli._run_rclpy(args) == 2  # (genbacklash node checks the file before this)
    assert "parameter 'window' must lie in [20, 1e+07], got 5" in capfd.readouterr().err
