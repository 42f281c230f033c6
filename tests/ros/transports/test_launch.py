"""The launch_testing test (``launch_fed_node.py``) under the ``launch_test`` command, against
the session's ``colcon build`` of this repository.

launch_testing's pytest plugin cannot load under pytest 9 (pyproject.toml's addopts), so
the test runs as ROS documents it for that case: ``launch_test FILE``, which exits 0 only
when every test of the file passed (the node fed while it runs, then its exit code and output
after the launch shut it down). Skipped, with the reason, where launch_testing (not on PyPI:
it needs a sourced ROS 2 Jazzy installation) or colcon is missing.
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from ._ros2 import built_workspace, colcon_missing, domain_id, launch_missing, workspace_env

_MISSING = launch_missing() or colcon_missing()
pytestmark = pytest.mark.skipif(bool(_MISSING), reason=_MISSING or "-")

LAUNCH_TEST = Path(__file__).resolve().with_name("launch_fed_node.py")


def test_launch_file_brings_up_a_working_node(tmp_path_factory: pytest.TempPathFactory) -> None:
    ws = built_workspace(tmp_path_factory.mktemp("colcon"))
    domain = domain_id()
    env = workspace_env(ws, domain)
    env["GENBACKLASH_TEST_DOMAIN_ID"] = str(domain)
    done = subprocess.run(
        [sys.executable, "-m", "launch_testing.launch_test", str(LAUNCH_TEST)],
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    output = done.stdout + done.stderr
    assert done.returncode == 0, output[-6000:]
    # the file's tests ran (an empty run exits 0 too)
    assert "test_estimate_diagnostics_and_compensated_command" in output, output[-3000:]
    assert "test_exit_code_is_zero" in output and "test_no_traceback" in output
    assert "FAILED" not in output and "Traceback" not in output, output[-6000:]
