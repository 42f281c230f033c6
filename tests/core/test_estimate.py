"""The online estimate: validation, uncertainty, model, dict form, and the shared interface."""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pytest

from genbacklash_core import (
    Estimate,
    EstimatorState,
    GenBacklashError,
    OnlineIdentifier,
    RecursiveIdentifier,
    WindowedIdentifier,
    paper_example,
    track,
)
from genbacklash_core.estimate import confidence_of, relative_std
from genbacklash_core.structure import Structure

STRUCTURE = Structure(3)
TRUTH = paper_example(1).model


def _estimate(**changes: object) -> Estimate:
    fields: dict[str, object] = {
        "structure": STRUCTURE,
        "parameters": TRUTH.parameters(),
        "covariance": np.diag(np.arange(1.0, 9.0)) * 1e-4,
        "residual": 0.03,
        "excitation": 0.7,
        "state": EstimatorState.CONVERGED,
        "confidence": 0.9,
        "samples": 1000,
        "reason": "settled",
    }
    fields.update(changes)
    return Estimate(**fields)  # type: ignore[arg-type]


def test_fields_and_names() -> None:
    est = _estimate()
    assert est.names == STRUCTURE.names()
    assert est.names[3] == "c_left"
    assert est.state is EstimatorState.CONVERGED
    assert est.state == "converged"  # a str enum
    assert est.available
    assert est.model == TRUTH


def test_state_given_as_text_is_converted() -> None:
    assert _estimate(state="no_excitation").state is EstimatorState.NO_EXCITATION


def test_five_states() -> None:
    assert [s.value for s in EstimatorState] == [
        "warming_up",
        "converging",
        "converged",
        "no_excitation",
        "diverged",
    ]


def test_frozen_and_read_only() -> None:
    est = _estimate()
    with pytest.raises(dataclasses.FrozenInstanceError):
        est.samples = 3  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        est.parameters[0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        est.covariance[0, 0] = 1.0


def test_input_arrays_are_copied() -> None:
    p = TRUTH.parameters()
    est = _estimate(parameters=p)
    p[0] = 99.0
    assert est.parameters[0] == TRUTH.m_left[0]


def test_std_and_confidence_interval() -> None:
    est = _estimate()
    np.testing.assert_allclose(est.std(), np.sqrt(np.arange(1.0, 9.0)) * 1e-2)
    low, high = est.confidence_interval(0.95)
    np.testing.assert_allclose(high - est.parameters, 1.959964 * est.std(), rtol=1e-6)
    np.testing.assert_allclose(est.parameters - low, high - est.parameters)
    low68, high68 = est.confidence_interval(0.6827)
    assert np.all(high68 - low68 < high - low)


@pytest.mark.parametrize("level", [0.0, 1.0, -0.5, 1.5])
def test_confidence_interval_level(level: float) -> None:
    with pytest.raises(GenBacklashError, match="level must lie strictly between 0 and 1"):
        _estimate().confidence_interval(level)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"parameters": np.zeros(7)}, r"parameters must have shape \(8,\)"),
        ({"covariance": np.eye(7)}, r"covariance must have shape \(8, 8\)"),
        ({"state": "done"}, "state must be one of warming_up, converging"),
        ({"confidence": 1.5}, r"confidence must lie in \[0, 1\]"),
        ({"confidence": float("nan")}, r"confidence must lie in \[0, 1\]"),
        ({"excitation": -0.1}, r"excitation must lie in \[0, 1\]"),
        ({"samples": -1}, "samples must be a whole number >= 0"),
        ({"samples": 2.5}, "samples must be a whole number >= 0"),
        ({"samples": True}, "samples must be a whole number >= 0"),
        ({"structure": "cubic"}, "structure must be a Structure"),
    ],
)
def test_validation(changes: dict[str, object], message: str) -> None:
    with pytest.raises(GenBacklashError, match=message):
        _estimate(**changes)


def test_empty_has_no_model() -> None:
    est = Estimate.empty(STRUCTURE, samples=12)
    assert est.state is EstimatorState.WARMING_UP
    assert not est.available
    assert est.model is None
    assert est.confidence == 0.0
    assert np.all(np.isnan(est.parameters))
    assert np.all(np.isnan(est.std()))
    assert est.samples == 12


def test_invalid_parameters_have_no_model() -> None:
    p = TRUTH.parameters()
    p[3] = -0.1  # c_left <= 0
    assert _estimate(parameters=p).model is None


def test_cascade_model() -> None:
    ex = paper_example(3)
    structure = Structure.of(ex.model)
    size = structure.n_parameters
    est = _estimate(
        structure=structure, parameters=ex.model.parameters(), covariance=np.eye(size) * 1e-6
    )
    assert est.model == ex.model
    assert est.names[-3:] == ("a_2", "b_1", "b_2")
    assert est.to_dict()["model"]["linear"] == {"a": [1.0, 0.15], "b": [-0.2, 0.35]}


def test_to_dict_is_json_ready() -> None:
    out = _estimate().to_dict()
    assert out["state"] == "converged"
    assert out["samples"] == 1000
    assert list(out["parameters"]) == list(STRUCTURE.names())
    assert out["parameters"]["c_left"] == pytest.approx(0.7)
    assert out["std"]["m_left_1"] == pytest.approx(0.01)
    assert out["model"]["model"] == "backlash"
    assert out["model"]["backlash"]["m_left"] == [0.5, -0.3, 0.3]
    json.dumps(out, allow_nan=False)
    empty = Estimate.empty(STRUCTURE).to_dict()
    assert empty["residual"] is None
    assert empty["parameters"]["c_left"] is None
    assert empty["model"] is None
    json.dumps(empty, allow_nan=False)


def test_with_samples_shares_arrays() -> None:
    est = _estimate()
    later = est.with_samples(1500)
    assert later.samples == 1500 and est.samples == 1000
    assert later.parameters is est.parameters
    assert later.state is est.state


def test_trusted_lazy_covariance_runs_once() -> None:
    calls: list[int] = []

    def factory() -> np.ndarray:
        calls.append(1)
        return np.eye(8) * 4e-4

    est = Estimate.trusted(
        STRUCTURE,
        TRUTH.parameters(),
        factory,
        0.02,
        0.5,
        EstimatorState.CONVERGING,
        0.4,
        10,
        "",
    )
    assert isinstance(est, Estimate)
    assert not calls
    np.testing.assert_allclose(est.std(), 0.02)
    est.std()
    assert est.with_samples(11).covariance is est.covariance
    assert len(calls) == 1
    with pytest.raises(ValueError, match="read-only"):
        est.covariance[0, 0] = 0.0


def test_relative_std_and_confidence() -> None:
    p = np.array([2.0, 0.5])
    assert relative_std(p, np.diag([0.01, 0.04])) == pytest.approx(0.1)
    assert confidence_of(EstimatorState.CONVERGED, 0.02, 0.02) == pytest.approx(0.5)
    assert confidence_of(EstimatorState.CONVERGED, 0.0, 0.02) == 1.0
    assert confidence_of(EstimatorState.NO_EXCITATION, 0.002, 0.02) > 0.98
    assert confidence_of(EstimatorState.CONVERGING, 0.0, 0.02) == 0.5
    assert confidence_of(EstimatorState.WARMING_UP, 0.0, 0.02) == 0.0
    assert confidence_of(EstimatorState.DIVERGED, 0.0, 0.02) == 0.0
    assert confidence_of(EstimatorState.CONVERGED, math.nan, 0.02) == 0.0


# --------------------------------------------------------------------------- the interface


@pytest.mark.parametrize("cls", [WindowedIdentifier, RecursiveIdentifier])
def test_both_identifiers_share_the_interface(cls: type) -> None:
    ident: OnlineIdentifier = cls(degree=3)
    data = paper_example(1).generate(seed=4, n_samples=700)
    assert ident.estimate.state is EstimatorState.WARMING_UP
    first = ident.update(float(data.u[0]), float(data.y[0]))
    assert first.samples == 1 and first.model is None
    est = ident.update_many(data.u[1:], data.y[1:])
    assert est is ident.estimate
    assert est.samples == 700
    assert est.state in (EstimatorState.CONVERGED, EstimatorState.CONVERGING)
    assert est.model is not None
    assert 0.0 < est.confidence <= 1.0
    assert 0.0 < est.excitation <= 1.0
    assert 0.0 < est.residual < 0.1
    assert np.all(est.std() > 0.0)
    json.dumps(est.to_dict(), allow_nan=False)
    ident.reset()
    assert ident.estimate.state is EstimatorState.WARMING_UP
    assert ident.estimate.samples == 0


def test_track_returns_one_estimate_per_chunk() -> None:
    data = paper_example(1).generate(seed=2, n_samples=1000)
    trace = track(WindowedIdentifier(3), data.u, data.y, every=300)
    assert [e.samples for e in trace] == [300, 600, 900, 1000]
    assert trace[0].available


@pytest.mark.parametrize("every", [0, -3, 2.5, True])
def test_track_rejects_bad_chunks(every: object) -> None:
    with pytest.raises(GenBacklashError, match="every must be a whole number >= 1"):
        track(WindowedIdentifier(3), [0.0], [0.0], every=every)  # type: ignore[arg-type]


def test_track_rejects_mismatched_series() -> None:
    with pytest.raises(GenBacklashError, match="one-dimensional of one length"):
        track(WindowedIdentifier(3), [0.0, 1.0], [0.0])
