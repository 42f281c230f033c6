"""What the tests that need a real ROS 2 share: whether rclpy imports, and why not; a DDS
domain of their own; one ``colcon build`` of this repository per test session; the
environment of that workspace.

rclpy and the ROS message packages are imported lazily, so that this module imports (and is
collected for doctests) without ROS. The bundled ROS 2 Jazzy (``../shared/ros2``, GUIDE §5)
is found at ``/opt/ros2_jazzy`` or ``$GENBACKLASH_ROS2_PREFIX``.
"""

from __future__ import annotations

import importlib
import os
import random
import shutil
import subprocess
import sys
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]
ROS2_PREFIX = Path(os.environ.get("GENBACKLASH_ROS2_PREFIX") or "/opt/ros2_jazzy")

# What a colcon workspace needs of this repository (the bags, tests and benchmarks are not).
PACKAGE_FILES = ("pyproject.toml", "setup.py", "setup.cfg", "package.xml", "README.md")
PACKAGE_DIRS = ("resource", "launch", "config", "genbacklash_core", "genbacklash_ros")


@cache
def rclpy_missing() -> str:
    """Why rclpy cannot be used here, or ``""`` when it imports (the skip reason)."""
    try:
        importlib.import_module("rclpy")
        importlib.import_module("std_msgs.msg")
    except Exception as err:  # ImportError, or a shared library that does not load (OSError)
        if (ROS2_PREFIX / "setup.bash").is_file():
            return (
                f"rclpy cannot be imported ({type(err).__name__}: {err}); ROS 2 is installed "
                f"at {ROS2_PREFIX}: source {ROS2_PREFIX}/setup.bash before running the tests "
                "(.ci/run does)"
            )
        return (
            "rclpy cannot be imported: ROS 2 Jazzy is not installed here (rclpy is not on "
            "PyPI); install the bundle with `bash ../shared/ros2/install` as root and source "
            f"{ROS2_PREFIX}/setup.bash (.ci/run does both when ../shared/ros2 is there)"
        )
    return ""


@cache
def ros2_cli_missing() -> str:
    """Why the ``ros2`` command and colcon cannot be used here, or ``""``."""
    if reason := rclpy_missing():
        return reason
    if shutil.which("ros2") is None:
        return "the ros2 command is not on PATH: source the ROS 2 setup.bash"
    try:
        importlib.import_module("colcon_core")
        importlib.import_module("colcon_ros")
    except ImportError:
        return "colcon-core and colcon-ros are not installed (pip install -e '.[dev]')"
    return ""


def domain_id() -> int:
    """A DDS domain for one test run: other runs on this machine use other ones."""
    return 1 + (os.getpid() * 7919 + random.randrange(1_000_000)) % 200


def colcon_command() -> list[str]:
    """The colcon command of this Python environment (colcon-core from the dev extra)."""
    script = Path(sys.executable).with_name("colcon")
    if script.is_file():
        return [str(script)]
    return [
        sys.executable,
        "-c",
        "import sys; from colcon_core.command import main; sys.exit(main())",
    ]


def colcon_build(ws: Path) -> subprocess.CompletedProcess[str]:
    """Copy the package into ``ws/src`` and run a real ``colcon build`` there."""
    src = ws / "src" / "genbacklash"
    src.mkdir(parents=True)
    for name in PACKAGE_FILES:
        shutil.copy2(ROOT / name, src / name)
    for name in PACKAGE_DIRS:
        shutil.copytree(ROOT / name, src / name, ignore=shutil.ignore_patterns("__pycache__"))
    env = {k: v for k, v in os.environ.items() if not k.startswith("COLCON")}
    env["COLCON_HOME"] = str(ws / "colcon_home")  # no user defaults
    return subprocess.run(
        [*colcon_command(), "build", "--base-paths", "src", "--event-handlers", "console_direct-"],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )


_BUILT: dict[str, Path] = {}


def built_workspace(base: Path) -> Path:
    """A colcon workspace holding this repository, built once per test session (the first
    caller's ``base``); raises ``RuntimeError`` with colcon's output when the build fails."""
    if "ws" not in _BUILT:
        ws = base / "ws"
        done = colcon_build(ws)
        if done.returncode != 0:
            raise RuntimeError("colcon build failed:\n" + done.stdout[-3000:] + done.stderr[-3000:])
        _BUILT["ws"] = ws
    return _BUILT["ws"]


def workspace_env(ws: Path, domain: int) -> dict[str, str]:
    """This process's environment with the workspace's ``install/setup.sh`` sourced (colcon
    writes ``setup.bash`` only with the colcon-bash extension), on DDS domain ``domain``."""
    dumped = subprocess.run(
        ["sh", "-c", f'. "{ws}/install/setup.sh" && env -0'],
        capture_output=True,
        check=True,
        timeout=60,
    ).stdout.decode()
    env = dict(item.split("=", 1) for item in dumped.split("\0") if "=" in item)
    env["ROS_DOMAIN_ID"] = str(domain)
    env["PYTHONUNBUFFERED"] = "1"
    return env


def params_file(path: Path, **values: object) -> Path:
    """Write ``path``: config/params.yaml (every default, keyed as shipped) with ``values``
    changed; returns ``path``."""
    lines = []
    for line in (ROOT / "config" / "params.yaml").read_text().splitlines():
        name = line.strip().split(":", 1)[0]
        if line.startswith("    ") and name in values:
            line = f"    {name}: {values[name]}"
        lines.append(line)
    path.write_text("\n".join(lines) + "\n")
    return path
