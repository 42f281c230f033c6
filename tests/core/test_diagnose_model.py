"""The augmented model of the diagnosis: validation, simulation, Jacobian, fit, JSON."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from genbacklash_core import (
    Cascade,
    GenBacklashError,
    GeneralBacklash,
    LinearBlock,
    identify_backlash,
    paper_example,
    simulate_backlash,
    simulate_cascade,
)
from genbacklash_core.diagnose import AugmentedModel, Drift, Saturation, fit_model
from genbacklash_core.diagnose.effects.output_offset import centre_gap
from genbacklash_core.diagnose.model import drift_coordinate
from genbacklash_core.diagnose.spec import ModelSpec, anchors_of, shift_input
from genbacklash_core.diagnose.synthetic import random_walk_input
from genbacklash_core.samples import sample_breaks

from ._helpers import drifting_gap_data

BL = GeneralBacklash.ideal(1.0, 0.3, 0.2)
CURVED = GeneralBacklash((1.0, 0.05, 0.06), 0.3, (0.9, -0.04, 0.08), 0.25)
BLOCK = LinearBlock(a=(1.0, 0.15), b=(-0.9, 0.2))


def _input(seed: int = 0, n: int = 1500) -> np.ndarray:
    return random_walk_input(n, np.random.default_rng(seed))


# --------------------------------------------------------------------------- validation


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"delay": -1}, "delay must be >= 0"),
        ({"delay": 1.5}, "delay must be a whole number"),
        ({"offset": float("nan")}, "offset must be finite"),
        ({"offset": "1"}, "offset must be a number"),
        ({"drift": 0.1}, "drift must be a Drift"),
        ({"saturation": (0, 1)}, "saturation must be a Saturation"),
    ],
)
def test_augmented_model_rejects_bad_parts(kwargs: dict[str, object], match: str) -> None:
    with pytest.raises(GenBacklashError, match=match):
        AugmentedModel(BL, **kwargs)  # type: ignore[arg-type]


def test_parts_validate_themselves() -> None:
    with pytest.raises(GenBacklashError, match="base must be a GeneralBacklash"):
        AugmentedModel("backlash")  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match="at least one limit"):
        Saturation()
    with pytest.raises(GenBacklashError, match="low < high"):
        Saturation(1.0, 1.0)
    with pytest.raises(GenBacklashError, match="finite"):
        Saturation(None, float("inf"))
    with pytest.raises(GenBacklashError, match="basis"):
        Drift(0.1, "distance")  # type: ignore[arg-type]
    with pytest.raises(GenBacklashError, match="finite"):
        Drift(float("nan"))
    with pytest.raises(GenBacklashError, match="non-empty 1-D"):
        AugmentedModel(BL).simulate(np.zeros((2, 2)))


# --------------------------------------------------------------------------- simulation


def test_plain_model_simulates_like_the_core() -> None:
    u = _input()
    np.testing.assert_array_equal(AugmentedModel(CURVED).simulate(u), simulate_backlash(CURVED, u))
    cascade = Cascade(CURVED, BLOCK)
    np.testing.assert_allclose(
        AugmentedModel(cascade).simulate(u), simulate_cascade(cascade, u).y, atol=1e-12
    )


def test_each_part_does_what_it_says() -> None:
    u = _input(1)
    plain = AugmentedModel(CURVED).simulate(u)
    delayed = AugmentedModel(CURVED, delay=4).simulate(u)
    np.testing.assert_array_equal(delayed, simulate_backlash(CURVED, shift_input(u, 4)))
    np.testing.assert_allclose(AugmentedModel(CURVED, offset=0.7).simulate(u), plain + 0.7)
    limited = AugmentedModel(CURVED, saturation=Saturation(-0.5, 0.8)).simulate(u)
    np.testing.assert_array_equal(limited, np.clip(plain, -0.5, 0.8))
    still = AugmentedModel(CURVED, drift=Drift(0.0, "travel")).simulate(u)
    np.testing.assert_array_equal(still, plain)


def test_time_drift_is_the_wear_of_the_online_tests() -> None:
    bl = paper_example(1).model
    assert isinstance(bl, GeneralBacklash)
    u, _, c_left, c_right = drifting_gap_data(3, 2000, (0, 2000), growth=0.5, snr=1e9)
    # the helper grows each gap by 50% of its own size; ours by one rate for both sides
    equal = GeneralBacklash(bl.m_left, 0.75, bl.m_right, 0.75)
    _, y_equal, _, _ = drifting_gap_data(3, 2000, (0, 2000), growth=0.5, snr=1e9, model=equal)
    ours = AugmentedModel(equal, drift=Drift(0.5 * 0.75 / 2000, "time")).simulate(u)
    np.testing.assert_allclose(ours, y_equal, atol=1e-6)
    assert c_left[-1] > c_left[0] and c_right[-1] > c_right[0]


def test_drift_coordinates() -> None:
    assert drift_coordinate([0.0, 2.0, 1.0], "travel").tolist() == [0.0, 2.0, 3.0]
    with pytest.raises(GenBacklashError, match="basis"):
        drift_coordinate([0.0], "space")  # type: ignore[arg-type]


def test_centre_gap_keeps_the_behaviour() -> None:
    u = _input(2)
    model = AugmentedModel(Cascade(GeneralBacklash.ideal(0.8, 0.6, 0.1), BLOCK), offset=-0.4)
    centred = centre_gap(model)
    assert centred.backlash.c_left == pytest.approx(centred.backlash.c_right)
    np.testing.assert_allclose(centred.simulate(u, 0.3), model.simulate(u, 0.3), atol=1e-9)


# --------------------------------------------------------------------------- Jacobian


@pytest.mark.parametrize(
    ("model", "y_start"),
    [
        (AugmentedModel(CURVED, delay=3, drift=Drift(1e-4, "time")), 0.1),
        # from rest: the Jacobian holds the start state fixed, which for a cascade started
        # at a steady state depends on the offset (a short transient the fit can ignore)
        (AugmentedModel(Cascade(BL, BLOCK), offset=0.3, drift=Drift(2e-4, "travel")), None),
        (AugmentedModel(BL, offset=-0.2, saturation=Saturation(None, 0.9)), 0.1),
    ],
)
def test_jacobian_matches_finite_differences(model: AugmentedModel, y_start: float | None) -> None:
    u = _input(3, 800)
    spec = ModelSpec.of(model)
    theta = spec.vector(model)
    out = spec.simulate(theta, u, y_start)
    jac = spec.jacobian(theta, u, out, y_start)
    numeric = np.empty_like(jac)
    for i in range(theta.size):
        step = 1e-7 * max(1.0, abs(theta[i]))
        up, down = theta.copy(), theta.copy()
        up[i] += step
        down[i] -= step
        numeric[:, i] = (spec.simulate(up, u, y_start).y - spec.simulate(down, u, y_start).y) / (
            2 * step
        )
    error = np.linalg.norm(jac - numeric, axis=0) / np.maximum(
        np.linalg.norm(numeric, axis=0), 1e-9
    )
    assert np.all(error < 0.02), dict(zip(spec.names(), error.round(4), strict=True))


@pytest.mark.parametrize(
    ("model", "y_start"),
    [
        (AugmentedModel(CURVED, delay=2, offset=0.1, drift=Drift(1e-4, "time")), 0.1),
        (AugmentedModel(BL, offset=-0.2, saturation=Saturation(None, 0.9)), 0.1),
        (AugmentedModel(Cascade(BL, BLOCK), offset=0.3), None),  # simulates on through
    ],
)
def test_anchored_simulation_and_its_jacobian(model: AugmentedModel, y_start: float | None) -> None:
    """After a lost reading (``anchors``) a backlash restarts at the measurement; the
    Jacobian of that simulation still matches finite differences."""
    u = _input(7, 800)
    y = model.simulate(u, y_start) + np.random.default_rng(8).normal(0.0, 0.02, u.size)
    breaks = np.random.default_rng(9).random(u.size) < 0.3
    breaks[0] = True
    anchors = anchors_of(breaks)
    assert anchors is not None and not anchors[0] and anchors[1:].tolist() == breaks[1:].tolist()
    assert anchors_of(np.eye(1, 5, dtype=bool)[0]) is None
    spec = ModelSpec.of(model)
    theta = spec.vector(model)
    out = spec.simulate(theta, u, y_start, anchors, y)
    if spec.structure.cascade:
        np.testing.assert_array_equal(out.y, spec.simulate(theta, u, y_start).y)
    else:
        np.testing.assert_allclose(out.x[anchors], y[anchors] - model.offset)
    jac = spec.jacobian(theta, u, out, y_start, anchors)
    numeric = np.empty_like(jac)
    for i in range(theta.size):
        step = 1e-7 * max(1.0, abs(theta[i]))
        up, down = theta.copy(), theta.copy()
        up[i] += step
        down[i] -= step
        high = spec.simulate(up, u, y_start, anchors, y).y
        numeric[:, i] = (high - spec.simulate(down, u, y_start, anchors, y).y) / (2 * step)
    error = np.linalg.norm(jac - numeric, axis=0) / np.maximum(
        np.linalg.norm(numeric, axis=0), 1e-9
    )
    assert np.all(error < 0.02), dict(zip(spec.names(), error.round(4), strict=True))


def test_fit_with_breaks_recovers_the_truth_from_lossy_data() -> None:
    """Example 1 (a white input) with an offset and 30% of the samples lost."""
    example = paper_example(1)
    data = example.generate(1, n_samples=3000, snr=25)
    truth = AugmentedModel(example.model, offset=0.1)
    keep = np.random.default_rng(12).random(data.u.size) >= 0.3
    u, y = data.u[keep], data.y[keep] + 0.1
    breaks = sample_breaks(np.flatnonzero(keep))
    spec = ModelSpec.of(truth)
    theta = spec.vector(truth)
    fitted = fit_model(truth, u, y, breaks=breaks)
    np.testing.assert_allclose(spec.vector(fitted.model), theta, atol=0.02)
    paired = fit_model(truth, u, y)  # across the lost readings
    assert np.max(np.abs(spec.vector(paired.model) - theta)) > 0.05


def test_spec_round_trip_and_names() -> None:
    model = AugmentedModel(
        Cascade(CURVED, BLOCK), 2, 0.4, Drift(1e-4, "travel"), Saturation(-1.0, 2.0)
    )
    spec = ModelSpec.of(model)
    assert spec.names()[-4:] == ("offset", "drift_rate", "saturation_low", "saturation_high")
    assert spec.n_free == spec.n_parameters + 1  # the dead time counts
    assert spec.model(spec.vector(model)) == model


# --------------------------------------------------------------------------- fit


@pytest.mark.parametrize(
    "truth",
    [
        AugmentedModel(CURVED, delay=3),
        AugmentedModel(BL, drift=Drift(1.5e-4, "time")),
        AugmentedModel(BL, saturation=Saturation(None, 1.2)),
        AugmentedModel(Cascade(BL, LinearBlock(a=(1.0,), b=(-0.7,)))),
    ],
)
def test_fit_recovers_the_truth_from_a_rough_start(truth: AugmentedModel) -> None:
    u = _input(4, 2000)
    y = truth.simulate(u) + np.random.default_rng(5).normal(0.0, 0.01, u.size)
    spec = ModelSpec.of(truth)
    theta = spec.vector(truth)
    rough = theta * np.random.default_rng(6).uniform(0.9, 1.1, theta.size)
    fit = fit_model((spec, rough), u, y)
    assert fit.nrmse < 0.02
    np.testing.assert_allclose(spec.vector(fit.model), theta, rtol=0.05, atol=0.02)
    assert fit.bic < replace(fit, sse=4 * fit.sse).bic


def test_fit_refuses_an_invalid_start() -> None:
    u = _input(5)
    crossing = AugmentedModel(GeneralBacklash((1.0,), 0.1, (3.0,), 0.1))
    with pytest.raises(GenBacklashError, match="invalid start"):
        fit_model(crossing, u, u)


# --------------------------------------------------------------------------- JSON


def test_dict_round_trips() -> None:
    model = AugmentedModel(
        Cascade(CURVED, BLOCK), 2, 0.4, Drift(1e-4, "travel"), Saturation(None, 2.0)
    )
    data = model.to_dict()
    assert data["drift"] == {"rate": 1e-4, "basis": "travel"}
    assert data["saturation"] == {"low": None, "high": 2.0}
    assert AugmentedModel.from_dict(data) == model


def test_from_dict_reads_identify_json_and_rejects_junk() -> None:
    data = paper_example(1).generate(0)
    result = identify_backlash(data.u, data.y, 3)
    model = AugmentedModel.from_dict(result.to_dict())
    assert model.base == result.model and model.effects == ("curved_branches",)
    with pytest.raises(GenBacklashError, match="not a model description"):
        AugmentedModel.from_dict({"model": "backlash"})
    with pytest.raises(GenBacklashError, match="'backlash' or 'cascade'"):
        AugmentedModel.from_dict({**result.to_dict(), "model": "spring"})
