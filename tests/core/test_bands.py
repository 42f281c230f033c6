"""When the recursive identifier refits the bands' tracking term (genbacklash_core.online.bands)."""

from __future__ import annotations

import numpy as np

from genbacklash_core import RecursiveIdentifier, Structure
from genbacklash_core.online.bands import DRIFT_EVERY, BandSchedule
from genbacklash_core.online.memory import BinnedRows
from genbacklash_core.online.rows import SampleRing, row_width
from genbacklash_core.online.status import IdentifierStatus
from genbacklash_core.scenarios import OperationSettings, operation_record


def test_the_term_is_refitted_once_per_drift_every_samples_and_ticks_on_between() -> None:
    rec = operation_record(OperationSettings(duration=6.0), seed=0)
    u, y, b = rec.series()
    ident = RecursiveIdentifier(3)
    ident.update_many(u, y, b)
    memory = ident.memory
    structure = ident.structure
    theta = structure.theta(ident.estimate.parameters)
    status = IdentifierStatus(structure, sign_now=True, samples=1000)
    ring = SampleRing(2000)
    ring.extend(u[-2000:], y[-2000:], b[-2000:])
    bands = BandSchedule()
    bands.committed(status, theta, memory, ring)
    assert status.drift is not None and bands.next_drift == 1000 + DRIFT_EVERY
    first = status.drift
    status.samples = 1000 + DRIFT_EVERY - 1
    bands.committed(status, theta, memory, ring)
    assert status.drift is first and bands.ticks == DRIFT_EVERY - 1
    bands.restart()
    bands.committed(status, theta, memory, ring)
    assert status.drift is not first and bands.ticks == 0.0


def test_nothing_for_the_cascade() -> None:
    structure = Structure(3, 2, 2)
    status = IdentifierStatus(structure, sign_now=True, samples=500)
    bands = BandSchedule()
    memory = BinnedRows(row_width(structure), 4, 100, 2)
    bands.committed(status, np.zeros(structure.n_parameters), memory, SampleRing(10))
    assert status.drift is None and bands.committed_at == 500
