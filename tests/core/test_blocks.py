"""The recursive identifier's blocks (genbacklash_core.online.blocks)."""

from __future__ import annotations

import numpy as np

from genbacklash_core import EstimatorState, RecursiveIdentifier, paper_example
from genbacklash_core.online.blocks import HELD, RUNNING, BlockMachine
from genbacklash_core.online.queue import SampleQueue
from genbacklash_core.online.settings import RecursiveSettings
from genbacklash_core.online.status import IdentifierStatus
from genbacklash_core.structure import Structure


def test_a_batch_start_then_one_block_per_event() -> None:
    data = paper_example(1).generate(seed=0, n_samples=700)
    status = IdentifierStatus(Structure(3), sign_now=False)
    s = RecursiveSettings()
    machine = BlockMachine(status, s, SampleQueue())
    status.samples = 600
    machine.piece(data.u[:600], data.y[:600], np.zeros(600, dtype=bool), first=0)
    machine.event()
    assert machine.mode == RUNNING and machine.due == 600 + s.block
    version = machine.current.version
    status.samples = 700
    machine.piece(data.u[600:], data.y[600:], np.zeros(100, dtype=bool), first=600)
    machine.event()  # new rows: one iteration over the memory
    assert machine.current.version == version + 1
    assert machine.due == 700 + s.block


def test_blown_errors_hold_the_estimate_until_they_are_normal_again() -> None:
    ex = paper_example(1)
    data = ex.generate(seed=3, n_samples=6000)
    ident = RecursiveIdentifier(3)
    ident.update_many(data.u[:3000], data.y[:3000])
    y = data.y[3000:].copy()
    y[:400] += np.random.default_rng(0).normal(0.0, 2.0, 400)  # a sensor fault
    ident.update_many(data.u[3000:3400], y[:400])
    assert ident._machine.mode == HELD
    assert ident.estimate.state is EstimatorState.DIVERGED
    est = ident.update_many(data.u[3400:], y[400:])
    assert ident._machine.mode == RUNNING and est.state is EstimatorState.CONVERGED


def test_a_corrupted_state_is_stopped_and_restarted_from_the_memory() -> None:
    data = paper_example(1).generate(seed=4, n_samples=3000)
    ident = RecursiveIdentifier(3)
    ident.update_many(data.u[:2000], data.y[:2000])
    ident._current.theta[1] = -ident._current.theta[1]  # c_left < 0
    est = ident.update_many(data.u[2000:], data.y[2000:])
    assert ident.restarts == 1 and est.available
