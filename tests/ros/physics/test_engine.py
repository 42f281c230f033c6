"""Stepping the drivetrain: held commands, pieces equal to one run, the closed-loop API."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco", reason="the physics drivetrains need mujoco (genbacklash[physics])")

from genbacklash_core import GenBacklashError
from genbacklash_ros.physics.engine import Drivetrain, Trajectory, simulate_commands
from genbacklash_ros.physics.variants import variant

MS = 1_000_000


def _commands(seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    t = np.arange(30, dtype=np.int64) * 10 * MS + rng.integers(0, 200_000, 30)
    return t, np.cumsum(rng.normal(0.0, 0.02, 30))


@pytest.mark.parametrize("name", ["near_ideal", "compliant"])
def test_a_run_cut_into_pieces_gives_the_same_bits(name: str) -> None:
    t, u = _commands(3)
    whole = simulate_commands(variant(name), t, u, 300 * MS)
    sim = Drivetrain(variant(name), position=float(u[0]))
    parts = [sim.follow(t, u, end) for end in range(10 * MS, 310 * MS, 10 * MS)]
    joined = Trajectory.concatenate(parts)
    for field in ("t_ns", "command", "motor", "slot", "load"):
        assert np.array_equal(getattr(whole, field), getattr(joined, field)), field


def test_a_command_acts_from_the_first_step_at_or_after_its_stamp() -> None:
    t = np.array([0, 1_100_000, 2_000_000])  # 1.1 ms: between steps (0.25 ms)
    u = np.array([0.0, 0.01, 0.02])
    run = simulate_commands(variant("near_ideal"), t, u, 3 * MS)
    # row k ends step k-1, which started at (k - 1) * 0.25 ms
    starts = run.t_ns[1:] - 250_000
    expected = np.where(starts >= 2 * MS, 0.02, np.where(starts >= 1_100_000, 0.01, 0.0))
    assert np.array_equal(run.command[1:], expected)
    assert run.t_ns[-1] == 3 * MS


def test_the_closed_loop_api_takes_one_command_at_a_time() -> None:
    sim = Drivetrain(variant("coasting"))
    seen = []
    for k in range(1, 21):  # a compensator would choose each command from what it saw
        part = sim.hold(0.005 * k, k * 10 * MS)
        seen.append(float(part.load_at(np.array([k * 10 * MS]))[0]))
    assert sim.time_ns == 200 * MS
    assert seen[-1] > 0.0  # the motor took up the play and pushed the load up
    with pytest.raises(GenBacklashError, match="outside the simulated"):
        part.load_at(np.array([0]))
    with pytest.raises(GenBacklashError, match="finite"):
        sim.advance(np.array([np.nan]))
    with pytest.raises(GenBacklashError, match="rate must lie"):
        Drivetrain(variant("coasting"), rate=100.0)
