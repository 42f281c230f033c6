"""``genbacklash demo --live``: a simulated arm and the identifier node in one ROS 2 graph."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.demo.arm import PERTURB, ArmSettings, SimulatedArm
from genbacklash_ros.demo.live import node_params_yaml
from genbacklash_ros.node.parameters import NodeParameters
from tests.ros.transports._ros2 import domain_id

pytest.importorskip("mujoco", reason="the physics drivetrains need mujoco (genbacklash[physics])")


def test_the_twin_and_the_arm_agree_on_the_same_commands() -> None:
    """Given the desired commands as its answers, the arm is its twin (the comparison the
    demo prints is fair: only the compensation differs)."""
    arm = SimulatedArm(ArmSettings(joints=("a", "b"), duration=2.0, encoder_rate=500.0))
    for tick in range(30):
        arm.obey(arm.desired(tick), tick)
        arm.step_to((tick + 1) * 10_000_000)
        for k in range(5):
            arm.loads_at(tick * 10_000_000 + 2_000_000 * (k + 1), tick)
    for obeyed, twin in arm.window():
        assert obeyed == twin and np.isfinite(obeyed)
    assert [v.acted.seconds for v in arm.verdicts()] == [0.0, 0.0]  # compensation never acted
    with pytest.raises(GenBacklashError, match="needs as many values"):
        arm.obey((0.1,), 0)


def test_readings_count_as_acted_while_the_arm_holds_another_command_and_a_second_after() -> None:
    """One command of 10 ms that differs from the desired one: the readings from its answer
    to SETTLE_S after it are counted apart, and the perturbed twin, its load started a
    quarter of the play away, differs from the first twin (the comparison's spread)."""
    rate = 500.0
    arm = SimulatedArm(ArmSettings(joints=("a",), duration=4.0, encoder_rate=rate))
    for tick in range(300):
        values = arm.desired(tick)
        if tick == 50:
            values = (values[0] + 0.01,)
        arm.obey(values, tick)
        arm.step_to((tick + 1) * 10_000_000)
        for k in range(5):
            arm.loads_at(tick * 10_000_000 + 2_000_000 * (k + 1), tick)
    (verdict,) = arm.verdicts()
    # readings 52, 54 ... 58 ms into tick 50, then all readings of 1 s after the next answer
    assert verdict.acted.seconds * rate == pytest.approx(5 + 1.0 * rate, abs=2)
    assert np.isfinite(verdict.acted.cut) and np.isfinite(verdict.half.spread)
    assert verdict.half.perturbed != verdict.half.twin  # the perturbed twin is another path
    assert PERTURB * arm.play > 0.01


def test_the_joints_move_differently() -> None:
    arm = SimulatedArm(ArmSettings(joints=("a", "b", "c"), duration=5.0))
    values = np.array([arm.desired(k) for k in range(arm.commands)])
    assert values.shape[1] == 3
    assert not np.allclose(values[:, 0], values[:, 1])


@pytest.mark.parametrize("bad", [{"joints": ()}, {"joints": ("a", "a")}, {"duration": 0.5}])
def test_settings_are_checked(bad: dict[str, object]) -> None:
    with pytest.raises(GenBacklashError):
        ArmSettings(**bad)  # type: ignore[arg-type]


def test_the_node_params_select_the_arm_joint() -> None:
    import yaml

    text = node_params_yaml(("joint_1",))
    values = yaml.safe_load(text)["/**/backlash_identifier"]["ros__parameters"]
    params = NodeParameters.from_mapping(values)
    assert (params.joint, params.command_index) == ("joint_1", 0)
    assert (params.command_type, params.encoder_type) == ("float64_multi_array", "joint_state")


def test_a_thread_priority_reaches_the_node_params() -> None:
    import yaml

    text = node_params_yaml(("joint_1", "joint_2"), thread_priority=30)
    values = yaml.safe_load(text)["/**/backlash_identifier"]["ros__parameters"]
    assert (
        NodeParameters.from_mapping(
            {k: v for k, v in values.items() if k not in ("joints", "command_indices")}
        ).thread_priority
        == 30
    )
    assert "thread_priority" not in node_params_yaml(("joint_1",))  # 0: the default


@pytest.mark.parametrize("value", ["100", "-1", "high"])
def test_a_bad_thread_priority_is_one_line_and_exit_2(
    value: str, capsys: pytest.CaptureFixture[str]
) -> None:
    from genbacklash_ros.cli.main import main

    with pytest.raises(SystemExit) as ended:
        main(["demo", "--live", "--thread-priority", value])
    assert ended.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith("genbacklash demo: error: argument --thread-priority: must")


def test_live_demo_runs_the_node_beside_a_simulated_arm() -> None:
    """The whole demo under the rclpy wheels: the node answers the arm's commands, publishes
    an estimate of the play, and the run ends with exit 0 and its table."""
    pytest.importorskip("rclpy", reason="demo --live needs rclpy (genbacklash[ros])")
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain_id()))
    proc = subprocess.run(
        [sys.executable, "-m", "genbacklash_ros.cli.main", "demo", "--live", "--duration", "25"],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
    )
    assert proc.returncode == 0, proc.stderr[-2000:] + proc.stdout[-2000:]
    out = proc.stdout
    answered = re.search(r"(\d+) of (\d+) commands answered", out)
    assert answered, out[-2000:]
    assert int(answered[1]) >= 0.9 * int(answered[2])
    row = re.search(r"^joint_1\s+(\S+)\s+(\S+)", out, re.M)
    assert row, out[-2000:]
    assert row[1] != "n/a", out[-3000:]  # the node estimated the play
    assert 0.5 < float(row[1]) / float(row[2]) < 2.0, out[-3000:]
    # a change of the compensation's state is printed with the node's reason
    assert re.search(r"^\s+\d+ s .*compensation off \(no estimate yet\)$", out, re.M), out[:2000]
