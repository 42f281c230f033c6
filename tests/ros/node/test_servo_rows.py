"""The servo model in the rows (issue 23, deliverable 2): batch rows, the node's align stage,
the parameters and the outputs that report it."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import GenBacklashError
from genbacklash_core.play import play_operator
from genbacklash_core.servo import ServoModel, estimate_servo
from genbacklash_ros.node.align import AlignedBatch, Aligner
from genbacklash_ros.node.messages import DiagnosticArray
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline
from genbacklash_ros.node.sample_rule import record_period, select_rows

MS = 1_000_000
SERVO = ServoModel(0.002, 0.005)


def _drivetrain(seed: int, seconds: float = 14.0) -> tuple[np.ndarray, ...]:
    """100 Hz held commands (moves between random targets), a servo, a play, 1 kHz readings
    with jitter and 2 % loss: (command stamps, commands, reading stamps, readings)."""
    rng = np.random.default_rng(seed)
    n_cmd = int(seconds * 100)
    targets = np.repeat(rng.uniform(-0.4, 0.4, n_cmd // 50 + 1), 50)[:n_cmd]
    commands = np.convolve(targets, np.ones(20) / 20, mode="same")
    cmd_t = np.arange(n_cmd, dtype=np.int64) * 10 * MS + 100_000
    t = (
        np.arange(n_cmd * 10, dtype=np.int64) * MS
        + 500_000
        + rng.integers(-40_000, 40_000, n_cmd * 10)
    )
    held = commands[np.searchsorted(cmd_t, t, side="right") - 1]
    x, _ = SERVO.output(t, held)
    y = play_operator(x - 0.04, x + 0.03, x[0])
    kept = rng.random(t.size) > 0.02
    return cmd_t, commands, t[kept], y[kept]


def test_select_rows_takes_the_servo_output_and_no_settling() -> None:
    cmd_t, cmd_u, t, y = _drivetrain(0)
    k = np.searchsorted(cmd_t, t, side="right") - 1
    rows = select_rows(t, k, cmd_u, y, bridge=True, settle_ns=5 * MS, servo=SERVO)
    assert rows.u.size == t.size  # every reading: no settling rule with a servo
    want, _ = SERVO.output(t, cmd_u[k])
    np.testing.assert_array_equal(rows.u, want)
    plain = select_rows(t, k, cmd_u, y)  # the stamps' breaks alone: none bridged
    np.testing.assert_array_equal(rows.breaks, plain.breaks)
    assert rows.servo == SERVO and rows.servo_fit is None


def test_auto_estimates_the_servo_from_the_rows() -> None:
    cmd_t, cmd_u, t, y = _drivetrain(1)
    k = np.searchsorted(cmd_t, t, side="right") - 1
    rows = select_rows(t, k, cmd_u, y, bridge=True, servo="auto")
    assert rows.servo_fit is not None and rows.servo == rows.servo_fit.model
    assert rows.servo.dead_time == pytest.approx(SERVO.dead_time, abs=3e-4)
    assert rows.servo.time_constant == pytest.approx(SERVO.time_constant, abs=3e-4)


def _feed(
    align: Aligner, cmd_t: np.ndarray, cmd_u: np.ndarray, t: np.ndarray, y: np.ndarray
) -> list[AlignedBatch]:
    """Commands and readings in time order, taken in pieces of ~50 ms as the node does."""
    times = np.concatenate([cmd_t, t])
    kinds = np.concatenate([np.zeros(cmd_t.size, int), np.ones(t.size, int)])
    values = np.concatenate([cmd_u, y])
    order = np.lexsort((kinds, times))
    out = []
    for n, i in enumerate(order):
        if kinds[i] == 0:
            align.add_command(int(times[i]), float(values[i]))
        else:
            align.add_reading(int(times[i]), float(values[i]), stuck=False)
        if n % 57 == 0:
            batch = align.take(align.horizon(final=False))
            if batch is not None and batch.size:
                out.append(batch)
    batch = align.take(align.horizon(final=True), final=True)
    if batch is not None and batch.size:
        out.append(batch)
    return out


@pytest.mark.parametrize("servo", [SERVO, "auto"])
def test_the_node_takes_the_rows_batch_takes(servo: ServoModel | str) -> None:
    """The align stage, fed in pieces, hands on the rows select_rows makes of the same
    readings (the same modelled input, to the bit); auto holds them until its window."""
    cmd_t, cmd_u, t, y = _drivetrain(2)
    align = Aligner(
        use_header=True,
        grid_ns=0,
        wait_ns=100 * MS,
        settle_ns=5 * MS,
        servo=servo,  # type: ignore[arg-type]
        servo_window_ns=8_000 * MS,
    )
    batches = _feed(align, cmd_t, cmd_u, t, y)
    got_t = np.concatenate([b.times for b in batches])
    got_u = np.concatenate([b.us for b in batches])
    k = np.searchsorted(cmd_t, t, side="right") - 1
    if servo == "auto":
        assert batches[0].times[-1] - batches[0].times[0] >= 8_000 * MS  # held until then
        assert align.servo_fit is not None and align.servo == align.servo_fit.model
        first = batches[0].size
        breaks = select_rows(t[:first], k[:first], cmd_u, y[:first]).breaks
        fit = estimate_servo(t[:first], cmd_u[k[:first]], y[:first], breaks)
        assert fit.model == align.servo  # the window's samples, the batch estimate
        model = align.servo
    else:
        model = SERVO
    rows = select_rows(t, k, cmd_u, y, servo=model)
    np.testing.assert_array_equal(got_t, rows.t)
    np.testing.assert_array_equal(got_u, rows.u)
    assert all(not b.monotone.any() for b in batches if b.monotone is not None)  # no bridging
    # the commands ride along for the guard's second yardstick, with their own monotone
    # flags (the held window's batches concatenated): a servo-less aligner's, to the bit
    plain = Aligner(use_header=True, grid_ns=0, wait_ns=100 * MS, settle_ns=0)
    bare = _feed(plain, cmd_t, cmd_u, t, y)
    for key in ("us", "monotone"):
        want = np.concatenate([getattr(b, key) for b in bare])
        name = "commands" if key == "us" else "command_monotone"
        got = np.concatenate([getattr(b, name) for b in batches])
        np.testing.assert_array_equal(got, want)
    assert all(b.commands is None and b.command_monotone is None for b in bare)


def test_servo_parameters_are_validated_and_reported() -> None:
    assert NodeParameters().servo() is None  # the default keeps the command as the input
    assert NodeParameters(servo_model="auto").servo() == "auto"
    assert NodeParameters(model="cascade", servo_model="auto").servo() is None
    with pytest.raises(GenBacklashError, match="servo_model"):
        NodeParameters(servo_model="lead")  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match="servo_dead_time"):
        NodeParameters(servo_dead_time=-0.1)


def test_the_pipeline_reports_its_servo_in_diagnostics() -> None:
    cmd_t, cmd_u, t, y = _drivetrain(3, seconds=8.0)
    pipe = BacklashPipeline(
        NodeParameters(
            command_type="float64",
            encoder_type="float64",
            servo_model="auto",
            servo_window=4.0,
        )
    )
    assert pipe.servo == {"state": "estimating", "window": 4.0}
    times = np.concatenate([cmd_t, t])
    kinds = np.concatenate([np.zeros(cmd_t.size, int), np.ones(t.size, int)])
    values = np.concatenate([cmd_u, y])
    for i in np.lexsort((kinds, times)):
        if kinds[i] == 0:
            pipe.on_command_value(None, float(values[i]), int(times[i]))
        else:
            pipe.on_encoder_value(None, float(values[i]), int(times[i]))
    outputs = pipe.finish()
    servo = pipe.servo
    assert servo is not None and servo["state"] == "estimated"
    assert float(servo["dead_time"]) == pytest.approx(SERVO.dead_time, abs=5e-4)  # type: ignore[arg-type]
    diag = [o for o in outputs if o.topic == "diagnostics"][-1].message
    assert isinstance(diag, DiagnosticArray)
    values_ = {kv.key: kv.value for kv in diag.status[0].values}
    assert values_["servo_state"] == "estimated"
    assert float(values_["servo_time_constant"]) == pytest.approx(SERVO.time_constant, abs=5e-4)
    est = pipe.estimate
    assert est.available
    model = est.model
    assert model.c_left + model.c_right == pytest.approx(0.07, rel=0.03)  # type: ignore[union-attr]
    assert record_period(t) == pytest.approx(MS, rel=0.01)
