"""The identifiers' shared intake (genbacklash_core.online.base): a sample dropped at the end
of one ``update_many`` call breaks the chain before the *next* call's first sample."""

from __future__ import annotations

import numpy as np
import pytest

from genbacklash_core import RecursiveIdentifier, WindowedIdentifier, paper_example
from genbacklash_core.online import RecursiveSettings, WindowedSettings


def _identifiers() -> list[tuple[str, object]]:
    return [
        ("windowed", lambda: WindowedIdentifier(3, settings=WindowedSettings(nonfinite="drop"))),
        (
            "recursive",
            lambda: RecursiveIdentifier(3, settings=RecursiveSettings(nonfinite="drop")),
        ),
    ]


@pytest.mark.parametrize(("name", "make"), _identifiers())
@pytest.mark.parametrize("cut", [700, 1500, 2201])
def test_a_call_ending_on_a_dropped_sample_equals_one_call(
    name: str, make: object, cut: int
) -> None:
    data = paper_example(1).generate(7, n_samples=3000)
    u, y = data.u.copy(), data.y.copy()
    y[cut - 1] = np.nan  # the last sample of the first call is dropped
    whole = make()  # type: ignore[operator]
    chunked = make()  # type: ignore[operator]
    one = whole.update_many(u, y)
    chunked.update_many(u[:cut], y[:cut])
    two = chunked.update_many(u[cut:], y[cut:])
    assert np.array_equal(one.parameters, two.parameters), name
    assert one.samples == two.samples
    assert one.state == two.state


@pytest.mark.parametrize(("name", "make"), _identifiers())
def test_single_updates_carry_the_break_of_a_dropped_sample(name: str, make: object) -> None:
    data = paper_example(1).generate(8, n_samples=1500)
    u, y = data.u.copy(), data.y.copy()
    y[600] = np.inf
    whole = make()  # type: ignore[operator]
    single = make()  # type: ignore[operator]
    one = whole.update_many(u, y)
    for uk, yk in zip(u, y, strict=True):
        two = single.update(float(uk), float(yk))
    assert np.array_equal(one.parameters, two.parameters), name
