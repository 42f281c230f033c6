"""The ROS 2 packaging: colcon (ament_python) finds and installs the node (GUIDE §5)."""

from __future__ import annotations

import ast
import configparser
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from genbacklash_ros.node.parameters import PARAMETER_SPECS, NodeParameters, load_params_file

from .transports._ros2 import built_workspace, domain_id, rclpy_missing

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    tomllib = None

ROOT = Path(__file__).resolve().parents[2]


def _package() -> ET.Element:
    return ET.parse(ROOT / "package.xml").getroot()


def test_package_xml_format_3_ament_python() -> None:
    root = _package()
    assert root.tag == "package" and root.get("format") == "3"
    assert root.findtext("name") == "genbacklash_ros"
    assert root.findtext("export/build_type") == "ament_python"
    assert root.findtext("license") == "Apache-2.0"
    assert root.find("maintainer") is not None and root.find("maintainer").get("email")
    exec_deps = {e.text for e in root.findall("exec_depend")}
    for dep in (
        "rclpy",
        "std_msgs",
        "sensor_msgs",
        "diagnostic_msgs",
        "rcl_interfaces",
        "launch_ros",
        "python3-numpy",
        "python3-scipy",
        "python3-yaml",
        "python3-sqlalchemy",
        "python3-jinja2",
    ):
        assert dep in exec_deps, dep


def test_package_version_matches_pyproject() -> None:
    if tomllib is None:  # pragma: no cover
        return
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert _package().findtext("version") == project["version"]


def test_setup_stub_and_cfg() -> None:
    tree = ast.parse((ROOT / "setup.py").read_text())
    calls = [n for n in ast.walk(tree) if isinstance(n, ast.Call)]
    assert [c.func.id for c in calls if isinstance(c.func, ast.Name)] == ["setup"]
    assert all(not c.args and not c.keywords for c in calls), "setup.py must stay a stub"
    cfg = configparser.ConfigParser(interpolation=None)
    cfg.read(ROOT / "setup.cfg")
    assert cfg["develop"]["script_dir"] == "$base/lib/genbacklash_ros"
    assert cfg["install"]["install_scripts"] == "$base/lib/genbacklash_ros"
    assert (ROOT / "resource" / "genbacklash_ros").is_file()


def test_pyproject_installs_data_files_and_only_two_packages() -> None:
    if tomllib is None:  # pragma: no cover
        return
    data = tomllib.loads((ROOT / "pyproject.toml").read_text())
    tool = data["tool"]["setuptools"]
    include = tool["packages"]["find"]["include"]
    assert all(p.split(".")[0] in ("genbacklash_core", "genbacklash_ros") for p in include)
    files = tool["data-files"]
    assert files["share/ament_index/resource_index/packages"] == ["resource/genbacklash_ros"]
    assert files["share/genbacklash_ros"] == ["package.xml"]
    for target, sources in files.items():
        for source in sources:
            assert (ROOT / source).is_file(), (target, source)
    scripts = data["project"]["scripts"]
    assert scripts["backlash_identifier"] == "genbacklash_ros.cli.node:ros2_main"


def test_config_params_yaml_holds_every_default() -> None:
    params = load_params_file(ROOT / "config" / "params.yaml")
    assert params == NodeParameters()
    text = (ROOT / "config" / "params.yaml").read_text()
    for spec in PARAMETER_SPECS:
        assert f"    {spec.name}: " in text, spec.name


def test_launch_file_starts_the_node_with_the_params_file() -> None:
    source = (ROOT / "launch" / "backlash_identifier.launch.py").read_text()
    tree = ast.parse(source)
    names = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in names
    assert 'executable="backlash_identifier"' in source
    assert 'package="genbacklash_ros"' in source
    assert "params_file" in source


def test_colcon_build_installs_the_node(tmp_path_factory: pytest.TempPathFactory) -> None:
    """A real `colcon build` (ament_python) of a workspace holding this repository installs the
    node where `ros2 run` / `ros2 launch` look for it, and its entry point runs. The build is
    the test session's one (shared with the ros2 launch tests)."""
    try:
        import colcon_core  # noqa: F401
        import colcon_ros  # noqa: F401
    except ImportError:
        pytest.skip(
            "colcon-core and colcon-ros are not installed (pip install -e '.[dev]' installs them)"
        )
    ws = built_workspace(tmp_path_factory.mktemp("colcon"))

    prefix = ws / "install" / "genbacklash_ros"
    node = prefix / "lib" / "genbacklash_ros" / "backlash_identifier"
    assert node.is_file() and os.access(node, os.X_OK)  # where `ros2 run` looks
    share = prefix / "share"
    assert (share / "ament_index" / "resource_index" / "packages" / "genbacklash_ros").is_file()
    assert (share / "genbacklash_ros" / "package.xml").read_bytes() == (
        ROOT / "package.xml"
    ).read_bytes()
    assert (share / "genbacklash_ros" / "launch" / "backlash_identifier.launch.py").is_file()
    assert load_params_file(share / "genbacklash_ros" / "config" / "params.yaml") == (
        NodeParameters()
    )
    site = next(prefix.glob("lib/python3*/site-packages"))
    top = {p.name for p in site.iterdir() if not p.name.endswith(("-info", ".pth"))}
    # only our two packages: a top-level `launch` would shadow ROS's launch package
    assert top == {"genbacklash_core", "genbacklash_ros"}, top

    # The installed entry point runs: without rclpy the one-line reason; with rclpy the node
    # starts, here refusing a bad parameter with its one line. Exit status 2 either way.
    env = {k: v for k, v in os.environ.items() if not k.startswith("COLCON")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(site), env.get("PYTHONPATH")]))
    env["ROS_DOMAIN_ID"] = str(domain_id())
    ran = subprocess.run(
        [sys.executable, str(node), "--ros-args", "-p", "degree:=12"],
        cwd=ws,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert ran.returncode == 2, ran.stderr
    assert "Traceback" not in ran.stderr
    if rclpy_missing():
        assert "rclpy cannot be imported" in ran.stderr
    else:
        assert ran.stderr.strip().endswith("parameter 'degree' must lie in [1, 9], got 12")


def test_package_xml_passes_catkin_pkg_validation() -> None:
    """The manifest as colcon, rosdep and bloom read it (catkin_pkg, installed with colcon-ros)."""
    package = pytest.importorskip(
        "catkin_pkg.package", reason="catkin_pkg comes with colcon-ros (pip install -e '.[dev]')"
    )
    manifest = package.parse_package(str(ROOT / "package.xml"))
    manifest.validate()  # raises InvalidPackage with the reason
    assert manifest.package_format == 3
    assert manifest.get_build_type() == "ament_python"
    assert "rclpy" in {dep.name for dep in manifest.exec_depends}
