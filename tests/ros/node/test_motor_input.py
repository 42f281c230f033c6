"""A motor encoder as the gear's input (``gear_input: motor_encoder``; issue 23, deliverable 2).

The align stage pairs each load reading with the motor reading of its stamp and takes out
the readings whose motor reading was lost (the rows rules of
:func:`~genbacklash_ros.node.sample_rule.select_rows`, shared with the batch path); the
pipeline still compensates every command; on MuJoCo drivetrains (near-ideal, 20, 60 and
100 Hz servo bandwidth) the replayed pipeline reads the geometric play within 10 %, where
the command as the input with the same rows would need the settling rule; a CSV with a
``motor`` column and the bag give the same rows.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import GenBacklashError
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.bagio import read_aligned
from genbacklash_ros.bags.csvio import read_series_csv, write_readings_csv
from genbacklash_ros.bags.replay import replay
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, JOINT, MOTOR_TOPIC
from genbacklash_ros.node.align import Aligner
from genbacklash_ros.node.joints import JointSet
from genbacklash_ros.node.messages import Float64, Header, JointState, Time
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline
from genbacklash_ros.node.sample_rule import paired_keep, select_rows

try:
    import mujoco  # noqa: F401

    HAVE_MUJOCO = True
except ImportError:
    HAVE_MUJOCO = False
needs_mujoco = pytest.mark.skipif(not HAVE_MUJOCO, reason="needs mujoco (genbacklash[physics])")

MS = 1_000_000


def test_the_aligner_pairs_each_reading_with_the_motor_reading_of_its_stamp() -> None:
    align = Aligner(use_header=True, grid_ns=0, wait_ns=100 * MS, settle_ns=5 * MS, motor=True)
    align.add_command(0, 9.0)  # a command keeps its order only: never the input
    for k in range(1, 8):
        if k != 4:  # the motor reading of stamp 4 ms is lost
            align.add_motor(k * MS, 0.1 * k)
        align.add_reading(k * MS, 0.01 * k, stuck=False)
    batch = align.take(align.horizon(final=False))
    assert batch is not None
    assert batch.times.tolist() == [k * MS for k in (1, 2, 3, 5, 6, 7)]
    assert np.allclose(batch.us, [0.1 * k for k in (1, 2, 3, 5, 6, 7)])  # motor, no settling
    assert batch.unpaired == 1
    assert batch.resumed is not None and batch.resumed.tolist() == [
        False,
        False,
        False,
        True,
        False,
        False,
    ]


def test_a_reading_waits_for_its_motor_reading() -> None:
    align = Aligner(use_header=True, grid_ns=0, wait_ns=100 * MS, motor=True)
    align.add_command(0, 0.0)
    align.add_motor(1 * MS, 0.1)
    align.add_reading(1 * MS, 0.0, stuck=False)
    align.add_reading(2 * MS, 0.0, stuck=False)  # its motor reading has not come yet
    assert align.horizon(final=False) == 1 * MS


def test_paired_keep_and_select_rows_take_out_the_unpaired() -> None:
    assert paired_keep([10, 20, 30], [10, 20, 20], None).tolist() == [True, True, False]
    stamps = np.arange(1, 9) * 10
    motor_t = np.array([10, 20, 30, 50, 60, 70, 80])  # 40 lost
    k = np.searchsorted(motor_t, stamps, side="right") - 1
    rows = select_rows(
        stamps, k, np.arange(7.0), np.zeros(8), bridge=False, settle_ns=15, input_stamps=motor_t
    )
    assert rows.unpaired == 1
    assert rows.t.tolist() == [10, 20, 30, 50, 60, 70, 80]
    assert rows.u.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0]  # no settling
    assert rows.breaks.tolist() == [True, False, False, True, False, False, False]
    bridged = select_rows(stamps, k, np.arange(7.0), np.zeros(8), bridge=True, input_stamps=motor_t)
    assert not bridged.breaks[3]  # a lost reading along a monotone motor path: bridged


def test_the_parameters_check_the_motor_input() -> None:
    params = NodeParameters(gear_input="motor_encoder", motor_encoder_type="float64")
    assert params.motor_input and params.motor_joint_name == ""
    assert NodeParameters(joint="a", motor_joint="m").motor_joint_name == "m"
    with pytest.raises(GenBacklashError, match="must be one of 'command', 'motor_encoder'"):
        NodeParameters(gear_input="motor")
    with pytest.raises(GenBacklashError, match="needs sample_period 0"):
        NodeParameters(gear_input="motor_encoder", sample_period=0.002)
    with pytest.raises(GenBacklashError, match="'joints' takes gear_input command only"):
        JointSet.from_mapping(
            {"joints": ["a", "b"], "command_indices": [0, 1], "gear_input": "motor_encoder"}
        )


def _reading(t_ns: int, value: float) -> JointState:
    return JointState(Header(Time.from_ns(t_ns)), ("j",), (value,))


def test_the_pipeline_identifies_from_the_motor_and_compensates_every_command() -> None:
    """A play operator between the motor and the load, a servo that lags the command: the
    identifier's input is the motor's reading, every command is compensated."""
    rng = np.random.default_rng(11)
    params = NodeParameters(command_type="float64", gear_input="motor_encoder", degree=1)
    pipe = BacklashPipeline(params)
    c_left, c_right = 0.03, 0.02
    n = 6000
    t = np.arange(n) * MS
    command = np.repeat(rng.uniform(-1, 1, n // 100), 100)
    motor = np.empty(n)
    m = 0.0
    for k in range(n):  # a first-order servo, 15 ms: far from the command at each step
        m += (command[k] - m) * (1 - np.exp(-1 / 15))
        motor[k] = m
    load = np.empty(n)
    x = 0.0
    for k in range(n):
        x = min(max(x, motor[k] - c_right), motor[k] + c_left)  # GUIDE §2's clamp
        load[k] = x
    sent = 0
    for k in range(n):
        if k % 100 == 0:
            out = pipe.on_command(Float64(float(command[k])), int(t[k]))
            sent += sum(o.topic == "compensated_command" for o in out)
        if k % 97 != 5:  # some motor readings lost
            pipe.on_motor(_reading(int(t[k]), float(motor[k])), int(t[k]) + 100_000)
        pipe.on_encoder(_reading(int(t[k]), float(load[k])), int(t[k]) + 150_000)
    pipe.finish()
    est = pipe.estimate
    assert sent == n // 100
    assert est.model is not None
    assert abs(est.model.c_left - c_left) < 2e-3 and abs(est.model.c_right - c_right) < 2e-3
    assert pipe.stats.dropped["motor_missing"] == len([k for k in range(n) if k % 97 == 5])
    assert pipe.stats.dropped["before_first_command"] == 0
    # a motor message of the wrong type is dropped with the reason; a command-input node
    # ignores motor messages
    assert pipe.on_motor(Float64(0.0), int(t[-1]) + MS) == []
    assert pipe.stats.dropped["motor_invalid"] == 1
    plain = BacklashPipeline(NodeParameters(command_type="float64"))
    assert plain.on_motor(_reading(MS, 0.0), MS) == []


@pytest.fixture(scope="module")
def near_ideal_bags(tmp_path_factory: pytest.TempPathFactory) -> dict[float, tuple[Path, float]]:
    from genbacklash_ros.physics import variant, write_physics_bag

    root = tmp_path_factory.mktemp("motor_bags")
    out = {}
    for bandwidth in (20.0, 60.0, 100.0):
        p = variant("near_ideal", bandwidth=bandwidth)
        bag = root / f"near_ideal-{bandwidth:g}"
        write_physics_bag(bag, p, OperationSettings(duration=20.0), seed=1, motor_encoder=True)
        out[bandwidth] = (bag, p.c_left + p.c_right)
    return out


@needs_mujoco
@pytest.mark.parametrize("bandwidth", [20.0, 60.0, 100.0])
def test_replay_with_the_motor_encoder_reads_the_geometric_play(
    near_ideal_bags: dict[float, tuple[Path, float]], bandwidth: float, tmp_path: Path
) -> None:
    bag, geometric = near_ideal_bags[bandwidth]
    result = replay(
        bag,
        tmp_path / "out",
        command_topic=COMMAND_TOPIC,
        encoder_topic=ENCODER_TOPIC,
        motor_topic=MOTOR_TOPIC,
        joint=JOINT,
    )
    model = result.estimate.model
    assert model is not None
    assert abs((model.c_left + model.c_right) / geometric - 1.0) < 0.10
    assert result.params.gear_input == "motor_encoder"
    assert result.stats.compensated == result.stats.commands > 0
    assert result.stats.dropped["motor_missing"] > 0  # 2 % of the motor readings lost
    # the batch path takes the same rows from the bag and from a CSV of its readings
    series = read_aligned(bag, COMMAND_TOPIC, ENCODER_TOPIC, joint=JOINT, motor_topic=MOTOR_TOPIC)
    csv = tmp_path / "r.csv"
    write_readings_csv(csv, series.t, series.u, series.y, motor=True)
    for bridge in (True, False):
        from_bag = read_aligned(
            bag,
            COMMAND_TOPIC,
            ENCODER_TOPIC,
            joint=JOINT,
            motor_topic=MOTOR_TOPIC,
            bridge=bridge,
            settle_ns=5 * MS,  # not applied to a motor input
        )
        from_csv = read_series_csv(csv, bridge=bridge, settle_ns=5 * MS)
        assert np.array_equal(from_bag.u, from_csv.u)
        assert np.array_equal(from_bag.y, from_csv.y)
        assert from_csv.breaks is not None
        assert np.array_equal(from_bag.breaks, from_csv.breaks)
