"""The ROS 2 packaging: colcon (ament_python) finds and installs the node (GUIDE §5)."""

from __future__ import annotations

import ast
import configparser
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

from genbacklash_ros.parameters import PARAMETER_SPECS, NodeParameters, load_params_file

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
    assert scripts["backlash_identifier"] == "genbacklash_ros.node_cli:ros2_main"


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
