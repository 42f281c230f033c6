"""What the online identifiers publish (genbacklash_core.online.publish)."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import EstimatorState, RecursiveIdentifier, WindowedIdentifier
from genbacklash_core.online import RecursiveSettings, WindowedSettings
from genbacklash_core.scenarios import OperationSettings, operation_record


@pytest.mark.parametrize(
    "make",
    [
        lambda: WindowedIdentifier(3, settings=WindowedSettings(idle_samples=500)),
        lambda: RecursiveIdentifier(3, settings=RecursiveSettings(idle_samples=500)),
    ],
    ids=["windowed", "recursive"],
)
def test_an_estimate_at_rest_is_reused_then_held_with_a_fading_confidence(make: object) -> None:
    rec = operation_record(OperationSettings(duration=10.0), seed=1)
    u, y, b = rec.series()
    ident = make()  # type: ignore[operator]
    est = ident.update_many(u, y, b)
    assert est.state is EstimatorState.CONVERGED
    rest = ident.update(float(u[-1]), float(y[-1]))
    # between events only the sample count changes: the same parameters, republished
    assert rest.samples == est.samples + 1
    assert np.array_equal(rest.parameters, est.parameters)
    held = ident.update_many(np.full(3000, u[-1]), np.full(3000, y[-1]))
    assert held.state is EstimatorState.NO_EXCITATION
    assert held.reason.startswith("estimate held")
    assert held.confidence < est.confidence
    assert np.array_equal(held.parameters, est.parameters)


def test_the_warming_up_reason_carries_the_excitation_advice() -> None:
    for ident in (WindowedIdentifier(1), RecursiveIdentifier(1)):
        est = ident.update_many(np.linspace(0.0, 1.0, 400), np.linspace(0.0, 0.9, 400))
        assert est.state is EstimatorState.WARMING_UP
        assert est.reason.endswith("the left branch is not covered yet: move the joint down")
