"""What the tests that need a real ROS 2 share: whether rclpy, the ``ros2`` command, launch and
colcon are there, and why not; a DDS domain of their own; one ``colcon build`` of this
repository per test session; the environment of that workspace.

rclpy and the ROS message packages are imported lazily, so that this module imports (and is
collected for doctests) without ROS. They come from the ROS 2 Jazzy wheels on PyPI (the ``ros``
extra, part of ``dev``: GUIDE §5) or from a sourced ROS 2 installation. ``ros2`` (ros2cli),
``launch``/``launch_ros``/``launch_testing`` and ``rosbag2`` are not on PyPI: the tests that need
them run only in a sourced ROS 2 Jazzy installation and skip elsewhere with that reason.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import random
import shutil
import subprocess
import sys
from functools import cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]

# What a colcon workspace needs of this repository (the bags, tests and benchmarks are not).
PACKAGE_FILES = ("pyproject.toml", "setup.py", "setup.cfg", "package.xml", "README.md")
PACKAGE_DIRS = ("resource", "launch", "config", "genbacklash_core", "genbacklash_ros")


# the part of a skip reason that says where the pieces missing from PyPI come from
NOT_ON_PYPI = (
    "not on PyPI (the ros extra has rclpy and the messages only): install ROS 2 Jazzy (apt) "
    "and source it"
)


@cache
def rclpy_missing() -> str:
    """Why rclpy cannot be used here, or ``""`` when it imports (the skip reason)."""
    try:
        importlib.import_module("rclpy")
        importlib.import_module("std_msgs.msg")
    except Exception as err:  # ImportError, or a shared library that does not load (OSError)
        return (
            f"rclpy cannot be imported ({type(err).__name__}: {err}): install the ROS 2 wheels "
            "with pip install -e '.[ros]' (included in '.[dev]'), or source a ROS 2 Jazzy "
            "installation"
        )
    return ""


def ros2_command_missing() -> str:
    """Why there is no ``ros2`` command here, or ``""`` (without importing rclpy)."""
    if shutil.which("ros2") is None:
        return f"the ros2 command is not on PATH: ros2cli is {NOT_ON_PYPI}"
    return ""


@cache
def ros2_cli_missing() -> str:
    """Why the ``ros2`` command cannot be used here, or ``""``."""
    return rclpy_missing() or ros2_command_missing()


@cache
def launch_missing() -> str:
    """Why ROS 2 launch (``ros2 launch``, ``launch_test``) cannot be used here, or ``""``.

    Looked up by ``launch_ros`` and ``launch_testing``: a bare ``import launch`` would find this
    repository's ``launch/`` directory (the launch files) as a namespace package."""
    if reason := rclpy_missing():
        return reason
    for name in ("launch_ros", "launch_testing"):
        if importlib.util.find_spec(name) is None:
            return (
                f"{name} cannot be imported: ROS 2 launch (launch, launch_ros, launch_testing) "
                f"is {NOT_ON_PYPI}"
            )
    return ""


@cache
def colcon_missing() -> str:
    """Why ``colcon build`` of this repository cannot run here, or ``""``."""
    try:
        importlib.import_module("colcon_core")
        importlib.import_module("colcon_ros")
    except ImportError:
        return "colcon-core and colcon-ros are not installed (pip install -e '.[dev]')"
    return ""


def ros2_launch_missing() -> str:
    """Why ``ros2 launch`` of this repository's colcon build cannot run here, or ``""``."""
    return ros2_cli_missing() or launch_missing() or colcon_missing()


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
