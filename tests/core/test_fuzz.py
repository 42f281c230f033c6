"""Fuzzing every public core entry point: arbitrary input gives a result or a clear error.

"A clear error" is a :class:`~genbacklash_core.GenBacklashError` (or a subclass) with a
non-empty message; anything else escaping (IndexError, ZeroDivisionError, LinAlgError, a bare
ValueError from numpy, a RuntimeWarning turned into an error by the pytest configuration) is a
crash. "A result" is finite wherever the function promises finite numbers: model parameters,
simulated outputs, compensated commands, an available estimate's parameters.

The inputs mix ordinary values with huge (1e300), tiny (1e-300, subnormal), NaN and +-inf
samples, empty arrays, length mismatches, wrong shapes and dtypes, constant inputs and bad
parameters. Every test is derandomised (a fixed example sequence) so failures reproduce;
``GENBACKLASH_FUZZ_SCALE=10`` multiplies the number of examples for a deeper run.
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from genbacklash_core import (
    Cascade,
    CompensatorOptions,
    CompensatorState,
    Estimate,
    EstimatorState,
    GenBacklashError,
    GeneralBacklash,
    InverseBacklash,
    LinearBlock,
    NonFiniteInputError,
    RecursiveIdentifier,
    RecursiveSettings,
    Structure,
    WindowedIdentifier,
    WindowedSettings,
    check_excitation,
    compensate,
    compensate_step,
    count_reversals,
    hold_interval,
    identify_backlash,
    identify_cascade,
    nrmse,
    paper_example,
    play_operator,
    play_operator_loop,
    prepare_series,
    refine_output_error,
    simulate_backlash,
    simulate_backlash_loop,
    simulate_cascade,
    simulate_cascade_loop,
    simulate_linear,
    track,
)
from genbacklash_core.diagnose import diagnose

T = TypeVar("T")


SCALE = int(os.environ.get("GENBACKLASH_FUZZ_SCALE", "1"))  # > 1: a deeper (slower) run


def fuzz(examples: int) -> Callable[[Callable[..., None]], Callable[..., None]]:
    """Hypothesis settings of this module: derandomised, no deadline, no example database."""
    return settings(
        max_examples=examples * SCALE,
        deadline=None,
        derandomize=True,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large],
    )


# --------------------------------------------------------------------------- strategies

HUGE = 1e300
SPECIAL = (
    0.0,
    -0.0,
    1.0,
    -1.0,
    HUGE,
    -HUGE,
    1e150,
    -1e150,
    1e-300,
    -1e-300,
    5e-324,
    1.7976931348623157e308,
    -1.7976931348623157e308,
    math.nan,
    math.inf,
    -math.inf,
)

# scalars: ordinary, special, anything a float can be
values = st.one_of(st.floats(-3.0, 3.0), st.sampled_from(SPECIAL), st.floats())
finite_values = st.one_of(
    st.floats(-3.0, 3.0),
    st.sampled_from([v for v in SPECIAL if math.isfinite(v)]),
    st.floats(allow_nan=False, allow_infinity=False),
)
# things that are not numbers or not one-dimensional series
WEIRD = (
    None,
    "abc",
    b"1",
    [],
    [[1.0, 2.0], [3.0, 4.0]],
    [[1.0], [2.0, 3.0]],
    {"a": 1.0},
    1j,
    [1j, 2j],
    [1.0, "x"],
    ["1", "2"],
    True,
    object(),
    3.5,
)
weird = (
    st.sampled_from(WEIRD)
    | st.builds(lambda n: np.zeros((n, 2)), st.integers(0, 4))
    | st.just(np.array(["a", "b"]))
    | st.just(np.array([1.0, "x"], dtype=object))
)
scalars = values | st.sampled_from([None, "abc", 1j, True, [1.0], object()])
orders = st.one_of(
    st.integers(-2, 4),
    st.sampled_from([0, -1, 2.5, 3.0, math.nan, math.inf, "3", None, True, np.int64(2)]),
)
SIGNS = st.sampled_from([None, 1, -1, 1.0, -1.0, 0, 2, 0.5, math.nan, math.inf, "up", True])


def mostly(good: st.SearchStrategy[Any], bad: st.SearchStrategy[Any]) -> st.SearchStrategy[Any]:
    """``good`` five times out of six, else ``bad``: most examples get past validation."""
    return st.one_of(good, good, good, good, good, bad)


@st.composite
def series(draw: st.DrawFn, min_size: int = 0, max_size: int = 300) -> np.ndarray:
    """A 1-D float series: a base shape at a scale, with special values injected."""
    n = draw(st.integers(min_size, max_size))
    rng = np.random.default_rng(draw(st.integers(0, 2**32 - 1)))
    kind = draw(st.sampled_from(["uniform", "walk", "sine", "constant", "zeros", "ramp", "steps"]))
    t = np.arange(n, dtype=np.float64)
    if kind == "uniform":
        base = rng.uniform(-1.0, 1.0, n)
    elif kind == "walk":
        base = np.cumsum(rng.normal(0.0, 0.1, n))
    elif kind == "sine":
        base = np.sin(2 * np.pi * t / max(draw(st.integers(4, 200)), 1))
    elif kind == "constant":
        base = np.full(n, draw(finite_values))
    elif kind == "zeros":
        base = np.zeros(n)
    elif kind == "ramp":
        base = np.linspace(-1.0, 1.0, n)
    else:
        base = np.repeat(rng.uniform(-1.0, 1.0, n // 10 + 1), 10)[:n]
    scale = draw(st.sampled_from([1.0, 1.0, 1.0, 0.01, 1e-300, 1e-150, 1e50, 1e150, HUGE]))
    with np.errstate(over="ignore"):
        out = base * scale
    if n and draw(st.booleans()):
        for _ in range(draw(st.integers(1, 4))):
            out[draw(st.integers(0, n - 1))] = draw(st.sampled_from(SPECIAL))
    return out


@st.composite
def model_data(draw: st.DrawFn, min_size: int = 0, max_size: int = 300) -> np.ndarray:
    """``[u, y]`` of one of the paper's Examples 1-4 (so that an identification gets going)."""
    n = draw(st.integers(min_size, max_size))
    number = draw(st.sampled_from([1, 2, 3, 4]))
    seed = draw(st.integers(0, 2**16))
    data = paper_example(number).generate(seed, n_samples=max(n, 1))
    return np.stack([data.u[:n], data.y[:n]])


@st.composite
def pairs(draw: st.DrawFn, max_size: int = 300, min_size: int = 40) -> tuple[Any, Any]:
    """``(u, y)`` pairs: model data, arbitrary series, mismatched lengths or weird objects.

    ``min_size`` is the shortest model data (the other kinds may be shorter).
    """
    kind = draw(st.sampled_from(["model", "model", "series", "mismatch", "weird", "damaged"]))
    if kind == "model":
        u, y = draw(model_data(min_size, max_size))
        return u, y
    if kind == "damaged":
        u, y = draw(model_data(min_size, max_size))
        target = u if draw(st.booleans()) else y
        for _ in range(draw(st.integers(1, 3))):
            target[draw(st.integers(0, target.size - 1))] = draw(st.sampled_from(SPECIAL))
        return u, y
    if kind == "series":
        u = draw(series(0, max_size))
        return u, draw(series(u.size, u.size))
    if kind == "mismatch":
        return draw(series(0, 50)), draw(series(0, 50))
    return draw(weird | series(0, 30)), draw(weird | series(0, 30))


coefficient = st.one_of(
    st.floats(-2.0, 2.0),
    st.sampled_from([1e300, -1e300, 1e150, -1e150, 1e-300, 5e-324, 0.0]),
)
positive = st.one_of(st.floats(1e-3, 2.0), st.sampled_from([1e300, 1e150, 1e-300, 5e-324]))


@st.composite
def backlashes(draw: st.DrawFn, extreme: bool = True) -> GeneralBacklash:
    """Valid general backlashes, some with extreme coefficients."""
    degree = draw(st.integers(1, 4))
    sign = draw(st.sampled_from([1.0, -1.0]))
    first = positive if extreme else st.floats(0.1, 2.0)
    rest = coefficient if extreme else st.floats(-0.5, 0.5)
    gap = positive if extreme else st.floats(0.01, 1.0)
    m_left = (sign * draw(first), *(draw(rest) for _ in range(degree - 1)))
    m_right = (sign * draw(first), *(draw(rest) for _ in range(degree - 1)))
    return GeneralBacklash(m_left, draw(gap), m_right, draw(gap))


@st.composite
def linear_blocks(draw: st.DrawFn) -> LinearBlock:
    na = draw(st.integers(1, 3))
    nb = draw(st.integers(0, 3))
    a = (1.0, *(draw(coefficient) for _ in range(na - 1)))
    return LinearBlock(a=a, b=tuple(draw(coefficient) for _ in range(nb)))


@st.composite
def mild_linear_blocks(draw: st.DrawFn) -> LinearBlock:
    na = draw(st.integers(1, 3))
    nb = draw(st.integers(0, 2))
    a = (1.0, *(draw(st.floats(-0.5, 0.5)) for _ in range(na - 1)))
    return LinearBlock(a=a, b=tuple(draw(st.floats(-0.4, 0.4)) for _ in range(nb)))


mild_models = backlashes(extreme=False) | st.builds(
    Cascade, backlashes(extreme=False), mild_linear_blocks()
)
extreme_models = backlashes() | st.builds(Cascade, backlashes(), linear_blocks())
models = st.one_of(mild_models, mild_models, extreme_models)
any_models = mostly(models, weird)  # for a ``model`` argument that may be anything


def attempt(function: Callable[..., T], *args: Any, **kwargs: Any) -> T | None:
    """Call ``function``: its result, or None after a clear :class:`GenBacklashError`.

    Any other exception propagates and fails the test.
    """
    try:
        result = function(*args, **kwargs)
    except GenBacklashError as err:
        assert str(err).strip(), f"{type(err).__name__} without a message"
        event(f"raised {type(err).__name__}")
        return None
    event("returned")
    return result


def assert_finite(values: Any, shape: tuple[int, ...] | None = None) -> None:
    array = np.asarray(values, dtype=np.float64)
    if shape is not None:
        assert array.shape == shape
    assert np.all(np.isfinite(array)), array


def series_length(values: object) -> int | None:
    """Length of ``values`` when it is a 1-D numeric series, else None."""
    try:
        array = np.asarray(values, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    return array.size if array.ndim == 1 else None


# --------------------------------------------------------------------------- models


@fuzz(300)
@given(
    m_left=st.lists(values, max_size=4) | weird,
    c_left=scalars,
    m_right=st.lists(values, max_size=4) | weird,
    c_right=scalars,
)
def test_general_backlash_construction(
    m_left: Any, c_left: Any, m_right: Any, c_right: Any
) -> None:
    model = attempt(GeneralBacklash, m_left, c_left, m_right, c_right)
    if model is None:
        return
    assert_finite(model.parameters(), (2 * model.degree + 2,))
    assert model.c_left > 0 and model.c_right > 0
    assert model.parameter_names and model.degree >= 1
    again = attempt(GeneralBacklash.from_parameters, model.parameters(), model.degree)
    assert again == model


@fuzz(200)
@given(values=st.lists(values, max_size=10) | weird, degree=orders)
def test_backlash_from_parameters(values: Any, degree: Any) -> None:
    model = attempt(GeneralBacklash.from_parameters, values, degree)
    if model is not None:
        assert_finite(model.parameters())
        assert model.degree == degree


@fuzz(150)
@given(slope=scalars, c_left=scalars, c_right=scalars)
def test_ideal_backlash(slope: Any, c_left: Any, c_right: Any) -> None:
    model = attempt(GeneralBacklash.ideal, slope, c_left, c_right)
    if model is not None:
        assert_finite(model.parameters(), (4,))


@fuzz(250)
@given(model=backlashes(), u=series(0, 60) | weird, x0=scalars)
def test_backlash_evaluation(model: GeneralBacklash, u: Any, x0: Any) -> None:
    n = series_length(u)
    for function in (model.left, model.right):
        out = attempt(function, u)
        if out is not None:  # +-inf where the polynomial leaves the float range, never NaN
            assert not np.any(np.isnan(out))
    for simulate in (model.simulate, simulate_backlash, simulate_backlash_loop):
        args = (u, x0) if simulate == model.simulate else (model, u, x0)
        x = attempt(simulate, *args)
        if x is not None:
            assert n is not None
            assert_finite(x, (n,))


@fuzz(200)
@given(model=backlashes(), u_min=values, u_max=values)
def test_backlash_crossings(model: GeneralBacklash, u_min: float, u_max: float) -> None:
    found = attempt(model.crossings, u_min, u_max)
    if found is not None:
        assert all(math.isfinite(v) and u_min <= v <= u_max for v in found)
    separated = attempt(model.branches_separated, u_min, u_max)
    assert separated is None or isinstance(separated, bool)


@fuzz(200)
@given(a=st.lists(values, max_size=4) | weird, b=st.lists(values, max_size=4) | weird)
def test_linear_block_construction(a: Any, b: Any) -> None:
    block = attempt(LinearBlock, a, b)
    if block is None:
        return
    assert block.a[0] == 1.0
    assert_finite(block.parameters())
    assert isinstance(block.stable, bool)
    block.dc_gain  # noqa: B018 - may be inf or NaN for absurd coefficients, must not raise


@fuzz(200)
@given(block=linear_blocks(), x=series(0, 300) | weird)
def test_simulate_linear(block: LinearBlock, x: Any) -> None:
    n = series_length(x)
    for simulate in (block.simulate, lambda v: simulate_linear(block, v)):
        y = attempt(simulate, x)
        if y is not None:
            assert n is not None
            assert_finite(y, (n,))


@fuzz(150)
@given(backlash=backlashes() | weird, linear=linear_blocks() | weird)
def test_cascade_construction(backlash: Any, linear: Any) -> None:
    model = attempt(Cascade, backlash, linear)
    if model is not None:
        assert_finite(model.parameters())
        assert len(model.parameter_names) == model.parameters().size


@fuzz(200)
@given(values=st.lists(values, max_size=14) | weird, degree=orders, na=orders, nb=orders)
def test_cascade_from_parameters(values: Any, degree: Any, na: Any, nb: Any) -> None:
    model = attempt(Cascade.from_parameters, values, degree, na, nb)
    if model is not None:
        assert_finite(model.parameters())
        assert (model.backlash.degree, model.linear.na, model.linear.nb) == (degree, na, nb)


@fuzz(200)
@given(
    model=st.builds(Cascade, backlashes(), linear_blocks()), u=series(0, 300) | weird, x0=scalars
)
def test_cascade_simulation(model: Cascade, u: Any, x0: Any) -> None:
    n = series_length(u)
    for simulate in (simulate_cascade, simulate_cascade_loop):
        out = attempt(simulate, model, u, x0)
        if out is not None:
            assert n is not None
            assert_finite(out.x, (n,))
            assert_finite(out.y, (n,))
    y = attempt(model.simulate, u, x0)
    if y is not None:
        assert_finite(y, (n,))


@fuzz(100)
@given(model=weird, u=series(0, 20), x0=finite_values)
def test_simulate_rejects_non_models(model: Any, u: np.ndarray, x0: float) -> None:
    for simulate in (
        simulate_backlash,
        simulate_backlash_loop,
        simulate_cascade,
        simulate_cascade_loop,
        simulate_linear,
    ):
        args = (model, u) if simulate is simulate_linear else (model, u, x0)
        with pytest.raises(GenBacklashError, match="must be a"):
            simulate(*args)


@fuzz(200)
@given(degree=orders, na=orders, nb=orders, sign=SIGNS)
def test_structure_construction(degree: Any, na: Any, nb: Any, sign: Any) -> None:
    structure = attempt(Structure, degree, na, nb, sign)
    if structure is not None:
        assert structure.n_parameters == len(structure.names())
        assert_finite(structure.start())


# --------------------------------------------------------------------------- play operator


@fuzz(200)
@given(
    lo=series(0, 700) | weird,
    hi=series(0, 700) | weird,
    x0=scalars,
    same_length=st.booleans(),
)
def test_play_operator(lo: Any, hi: Any, x0: Any, same_length: bool) -> None:
    if same_length and series_length(lo) is not None and series_length(hi) is not None:
        hi = np.resize(np.asarray(hi, dtype=np.float64), np.asarray(lo).shape)
    fast = attempt(play_operator, lo, hi, x0)
    loop = attempt(play_operator_loop, lo, hi, x0)
    assert (fast is None) == (loop is None)
    if fast is not None and loop is not None:
        np.testing.assert_array_equal(fast, loop)
        assert not np.any(np.isnan(fast))


# --------------------------------------------------------------------------- data checks


@fuzz(200)
@given(uy=pairs(100), nonfinite=st.sampled_from(["raise", "drop", "skip", None, 1]))
def test_prepare_series(uy: tuple[Any, Any], nonfinite: Any) -> None:
    u, y = uy
    out = attempt(prepare_series, u, y, nonfinite)
    if out is not None:
        uu, yy = out
        assert uu.ndim == yy.ndim == 1 and uu.size == yy.size
        assert_finite(uu)
        assert_finite(yy)


@fuzz(200)
@given(uy=pairs(100), n_parameters=orders)
def test_excitation_checks(uy: tuple[Any, Any], n_parameters: Any) -> None:
    u, y = uy
    attempt(check_excitation, u, y, n_parameters)
    reversals = attempt(count_reversals, u)
    assert reversals is None or (isinstance(reversals, int) and reversals >= 0)


@fuzz(200)
@given(uy=pairs(100))
def test_nrmse(uy: tuple[Any, Any]) -> None:
    y, y_sim = uy
    value = attempt(nrmse, y, y_sim)
    if value is not None:
        assert isinstance(value, float) and not math.isnan(value) and value >= 0.0


# --------------------------------------------------------------------------- identification


def _check_result(result: Any, degree: int) -> None:
    event(f"converged={result.converged}")
    assert isinstance(result.converged, bool)
    assert isinstance(result.reason, str) and result.reason.strip()
    assert_finite(result.model.parameters())
    assert_finite(result.equation_error_model.parameters())
    assert not math.isnan(result.fit.nrmse)
    if result.converged:
        assert math.isfinite(result.fit.nrmse)
    backlash = result.model.backlash if isinstance(result.model, Cascade) else result.model
    assert backlash.degree == degree
    assert result.to_dict()["converged"] is result.converged


@fuzz(60)
@given(uy=pairs(300), degree=st.integers(1, 3), nonfinite=st.sampled_from(["raise", "drop"]))
def test_identify_backlash_data(uy: tuple[Any, Any], degree: int, nonfinite: str) -> None:
    u, y = uy
    result = attempt(identify_backlash, u, y, degree, nonfinite=nonfinite)  # type: ignore[arg-type]
    if result is not None:
        _check_result(result, degree)


@fuzz(40)
@given(
    uy=pairs(300),
    degree=st.integers(1, 3),
    na=st.integers(1, 2),
    nb=st.integers(0, 2),
    nonfinite=st.sampled_from(["raise", "drop"]),
)
def test_identify_cascade_data(
    uy: tuple[Any, Any], degree: int, na: int, nb: int, nonfinite: str
) -> None:
    u, y = uy
    result = attempt(identify_cascade, u, y, degree, na, nb, nonfinite=nonfinite)  # type: ignore[arg-type]
    if result is not None:
        _check_result(result, degree)
        assert isinstance(result.model, Cascade)


EXAMPLE1 = paper_example(1).generate(0, n_samples=200)
EXAMPLE3 = paper_example(3).generate(0, n_samples=200)


IDENTIFY_OPTIONS: dict[str, st.SearchStrategy[Any]] = {
    "degree": orders,
    "na": orders,
    "nb": orders,
    "sign": SIGNS,
    "start": any_models,
    "refine": st.sampled_from([True, False, None, "yes", np.bool_(True)]),
    "max_iterations": orders | st.sampled_from([10**9, 1.5, math.inf]),
    "tol": scalars,
    "nonfinite": st.sampled_from(["raise", "drop", "skip", None, 1]),
    "callback": st.sampled_from([None, "print", 3, lambda k, p: None]),
}


@fuzz(120)
@given(
    cascade=st.booleans(),
    bad=st.sampled_from(sorted(IDENTIFY_OPTIONS)),
    data=st.data(),
)
def test_identify_options(cascade: bool, bad: str, data: st.DataObject) -> None:
    """One option at a time takes an arbitrary value; the others are sensible."""
    example = paper_example(3 if cascade else 1)
    options: dict[str, Any] = {
        "degree": 3,
        "na": 2,
        "nb": 2,
        "sign": None,
        "start": data.draw(st.sampled_from([None, example.model])),
        "refine": True,
        "max_iterations": 10,
        "tol": 1e-4,
        "nonfinite": "raise",
        "callback": None,
    }
    options[bad] = data.draw(IDENTIFY_OPTIONS[bad], label=bad)
    if isinstance(options["max_iterations"], int) and options["max_iterations"] > 30:
        options["max_iterations"] = 30  # a huge limit is valid; keep the run short
    degree, na, nb = options.pop("degree"), options.pop("na"), options.pop("nb")
    if cascade:
        result = attempt(identify_cascade, EXAMPLE3.u, EXAMPLE3.y, degree, na, nb, **options)
    else:
        result = attempt(identify_backlash, EXAMPLE1.u, EXAMPLE1.y, degree, **options)
    if result is not None:
        _check_result(result, int(degree))


@fuzz(60)
@given(
    model=any_models,
    uy=pairs(200),
    x0=st.none() | mostly(finite_values, scalars),
    max_iterations=mostly(st.integers(0, 10), orders),
    tol=mostly(st.floats(0.0, 1e-3), scalars),
)
def test_refine_output_error(
    model: Any, uy: tuple[Any, Any], x0: Any, max_iterations: Any, tol: Any
) -> None:
    u, y = uy
    out = attempt(refine_output_error, model, u, y, x0=x0, max_iterations=max_iterations, tol=tol)
    if out is not None:
        assert_finite(out.model.parameters())
        assert math.isfinite(out.cost_start) and math.isfinite(out.cost_end)
        assert out.cost_end <= out.cost_start
        assert isinstance(out.reason, str) and out.reason


# --------------------------------------------------------------------------- online


def _check_estimate(estimate: Estimate, samples: int | None = None) -> None:
    event(f"state={estimate.state.value}")
    assert isinstance(estimate, Estimate)
    assert 0.0 <= estimate.confidence <= 1.0
    assert 0.0 <= estimate.excitation <= 1.0
    assert isinstance(estimate.state, EstimatorState)
    if samples is not None:
        assert estimate.samples == samples
    if estimate.available:
        assert_finite(estimate.parameters)
    else:  # no parameters: nothing a compensator may trust
        assert estimate.confidence == 0.0 and estimate.model is None
    estimate.to_dict()


def _online(kind: str, degree: int, na: int, nb: int, drop: bool) -> Any:
    if kind == "windowed":
        settings_w = WindowedSettings(
            window=150,
            refit_every=20,
            min_samples=60,
            excitation_window=60,
            nonfinite="drop" if drop else "raise",
        )
        return WindowedIdentifier(degree, na, nb, settings=settings_w)
    settings_r = RecursiveSettings(
        initial_samples=60,
        buffer=150,
        block=16,
        check_every=20,
        excitation_memory=50,
        nonfinite="drop" if drop else "raise",
    )
    return RecursiveIdentifier(degree, na, nb, settings=settings_r)


@fuzz(30)
@given(
    kind=st.sampled_from(["windowed", "recursive"]),
    cascade=st.booleans(),
    uy=pairs(400, min_size=100),
    drop=st.booleans(),
    per_sample=st.booleans(),
)
def test_online_identifiers(
    kind: str, cascade: bool, uy: tuple[Any, Any], drop: bool, per_sample: bool
) -> None:
    u, y = uy
    identifier = _online(kind, 3, 2 if cascade else 0, 2 if cascade else 0, drop)
    if per_sample:
        n = series_length(u)
        if n is None or series_length(y) != n:
            est = attempt(identifier.update, u, y)
            assert est is None or isinstance(est, Estimate)
            return
        for k, (uk, yk) in enumerate(zip(np.asarray(u, float), np.asarray(y, float), strict=True)):
            try:
                est = identifier.update(uk, yk)
            except NonFiniteInputError as err:  # NaN, inf, or too large for the regression
                assert not drop and "nonfinite='drop'" in str(err)
                assert not (abs(uk) < 1e30 and abs(yk) < 1e30)
                return
            _check_estimate(est)
            assert est.samples <= k + 1
    else:
        est = attempt(identifier.update_many, u, y)
        if est is not None:
            _check_estimate(est)
    _check_estimate(identifier.estimate)


@st.composite
def saved_estimates(draw: st.DrawFn) -> Any:
    """Estimates as a checkpoint may hold them: any model, covariance scale and residual."""
    model = draw(models)
    structure = Structure.of(model)
    size = structure.n_parameters
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    kind = draw(st.sampled_from(["diagonal", "random", "singular", "indefinite", "special"]))
    scale = draw(st.sampled_from([1e-6, 1.0, 0.0, -1.0, 1e-300, 1e300, 5e-324]))
    if kind == "diagonal":
        covariance = np.eye(size) * scale
    elif kind == "random":
        a = rng.normal(size=(size, size))
        covariance = a @ a.T * abs(scale)
    elif kind == "singular":
        v = rng.normal(size=size)
        covariance = np.outer(v, v)
    elif kind == "indefinite":
        covariance = np.diag(rng.normal(size=size))
    else:
        covariance = np.full((size, size), draw(st.sampled_from(SPECIAL)))
    return attempt(
        Estimate,
        structure,
        model.parameters(),
        covariance,
        draw(mostly(st.floats(1e-4, 1.0), values)),
        draw(st.floats(0.0, 1.0)),
        draw(st.sampled_from(list(EstimatorState))),
        draw(st.floats(0.0, 1.0)),
        draw(st.integers(0, 10**6)),
    )


@fuzz(100)
@given(
    kind=st.sampled_from(["windowed", "recursive"]),
    saved=mostly(saved_estimates(), weird),
    sign=st.sampled_from([None, 1, -1]),
    uy=model_data(0, 200),
)
def test_online_seed(kind: str, saved: Any, sign: Any, uy: np.ndarray) -> None:
    """Seeding from any saved estimate (a checkpoint) continues or fails clearly."""
    structure = saved.structure if isinstance(saved, Estimate) else Structure(3)
    cls: Any = WindowedIdentifier if kind == "windowed" else RecursiveIdentifier
    identifier = cls(structure.degree, structure.na, structure.nb, sign=sign)
    est = attempt(identifier.seed, saved)
    if est is None:
        _check_estimate(identifier.estimate, 0)  # unchanged
        return
    _check_estimate(est)
    assert est.available
    after = attempt(identifier.update_many, uy[0], uy[1])
    if after is not None:
        _check_estimate(after)


@fuzz(150)
@given(
    kind=st.sampled_from(["windowed", "recursive"]),
    degree=orders,
    na=orders,
    nb=orders,
    sign=SIGNS,
    settings_=st.none() | weird,
)
def test_online_construction(
    kind: str, degree: Any, na: Any, nb: Any, sign: Any, settings_: Any
) -> None:
    cls: Any = WindowedIdentifier if kind == "windowed" else RecursiveIdentifier
    identifier = attempt(cls, degree, na, nb, sign=sign, settings=settings_)
    if identifier is not None:
        _check_estimate(identifier.estimate, 0)
        est = attempt(identifier.update, 0.1, 0.2)
        assert est is not None
        _check_estimate(est, 1)


SETTING_VALUES = st.one_of(
    st.integers(-2, 300),
    st.floats(-1.0, 2.0),
    st.sampled_from([0, 1, 20, 0.0, 1.0, 1e-12, 1e200, math.inf, 10**12, "raise", "drop", True]),
    scalars,
)
FAST_WINDOWED = {"window": 150, "refit_every": 20, "min_samples": 60, "excitation_window": 60}
FAST_RECURSIVE = {"initial_samples": 60, "buffer": 150, "block": 16, "check_every": 20}


@fuzz(150)
@given(kind=st.sampled_from(["windowed", "recursive"]), data=st.data())
def test_online_settings(kind: str, data: st.DataObject) -> None:
    """One setting at a time takes an arbitrary value; valid settings then run on data."""
    cls: Any = WindowedSettings if kind == "windowed" else RecursiveSettings
    base: dict[str, Any] = dict(FAST_WINDOWED if kind == "windowed" else FAST_RECURSIVE)
    name = data.draw(st.sampled_from(sorted(cls.__dataclass_fields__)), label="name")
    base[name] = data.draw(SETTING_VALUES, label=name)
    chosen = attempt(cls, **base)
    if chosen is None:
        return
    sizes = ("window", "buffer", "initial_samples", "min_samples", "excitation_window")
    if any((getattr(chosen, field, None) or 0) > 10**5 for field in sizes):
        return  # valid, but a ring buffer that large is not what this test is about
    identifier: Any = (WindowedIdentifier if kind == "windowed" else RecursiveIdentifier)(
        3, settings=chosen
    )
    example = paper_example(1).generate(data.draw(st.integers(0, 100)), n_samples=300)
    _check_estimate(identifier.update_many(example.u, example.y), 300)
    _check_estimate(identifier.update(0.5, 0.2), 301)


@fuzz(60)
@given(uy=pairs(200), every=orders | st.sampled_from([1, 7, 50, 10**9]))
def test_track(uy: tuple[Any, Any], every: Any) -> None:
    u, y = uy
    identifier = _online("windowed", 1, 0, 0, False)
    out = attempt(track, identifier, u, y, every)
    if out is not None:
        for est in out:
            _check_estimate(est)


@fuzz(40)
@given(identifier=weird, u=series(1, 10))
def test_track_rejects_non_identifiers(identifier: Any, u: np.ndarray) -> None:
    attempt(track, identifier, u, u)


@fuzz(200)
@given(
    structure=st.builds(Structure, st.integers(1, 3)),
    parameters=st.lists(values, max_size=8) | weird,
    residual=scalars,
    excitation=scalars,
    state=st.sampled_from(["converged", "warming_up", "bogus", None, 3, EstimatorState.DIVERGED]),
    confidence=scalars,
    samples=orders | st.sampled_from([-5, 10**20, 1.5, "7"]),
    level=scalars,
)
def test_estimate_construction(
    structure: Structure,
    parameters: Any,
    residual: Any,
    excitation: Any,
    state: Any,
    confidence: Any,
    samples: Any,
    level: Any,
) -> None:
    size = structure.n_parameters
    if isinstance(parameters, list) and len(parameters) < size:
        parameters = (parameters * size)[:size] if parameters else [0.5] * size
    est = attempt(
        Estimate,
        structure,
        parameters,
        np.eye(size),
        residual,
        excitation,
        state,
        confidence,
        samples,
    )
    if est is None:
        return
    assert 0.0 <= est.confidence <= 1.0
    if est.available:
        assert_finite(est.parameters)
    est.to_dict()
    interval = attempt(est.confidence_interval, level)
    if interval is not None:
        assert interval[0].shape == (size,)


# --------------------------------------------------------------------------- compensation


@st.composite
def compensator_options(draw: st.DrawFn) -> Any:
    """None, or options with each field mostly sensible and sometimes anything (a bad
    combination falls back to the defaults after a clear error)."""
    if draw(st.booleans()):
        return None
    kwargs: dict[str, Any] = {}
    if draw(st.booleans()):
        kwargs["u_min"] = draw(mostly(st.floats(-5.0, 0.0), scalars))
        kwargs["u_max"] = draw(mostly(st.floats(0.1, 5.0), scalars))
    if draw(st.booleans()):
        kwargs["max_rate"] = draw(mostly(st.floats(1e-3, 10.0), scalars))
    if draw(st.booleans()):
        kwargs["smoothing"] = draw(mostly(st.integers(0, 5), orders))
    if draw(st.booleans()):
        kwargs["gate_low"] = draw(mostly(st.floats(0.0, 0.5), scalars))
        kwargs["gate_high"] = draw(mostly(st.floats(0.5, 1.0), scalars))
    if draw(st.booleans()):
        ranges = st.tuples(st.floats(-5.0, 0.0), st.floats(0.1, 5.0))
        kwargs["valid_range"] = draw(mostly(ranges, st.tuples(values, values) | weird))
    try:
        return CompensatorOptions(**kwargs)
    except GenBacklashError as err:
        assert str(err).strip()
        return CompensatorOptions()


@fuzz(200)
@given(
    model=any_models,
    options=compensator_options(),
    x_d=mostly(series(0, 80), weird),
    confidence=mostly(values, series(0, 80) | weird),
)
def test_compensate(model: Any, options: Any, x_d: Any, confidence: Any) -> None:
    u = attempt(compensate, model, x_d, options, confidence)
    if u is None:
        return
    opts = options or CompensatorOptions()
    assert_finite(u, (series_length(x_d),))
    assert np.all((opts.u_min <= u) & (u <= opts.u_max))
    if u.size > 1 and math.isfinite(opts.max_rate):
        assert np.all(np.abs(np.diff(u)) <= opts.max_rate)


@fuzz(200)
@given(
    model=models,
    options=compensator_options(),
    x0=mostly(finite_values, scalars),
    u0=st.none() | mostly(finite_values, scalars),
    steps=st.lists(st.tuples(mostly(values, weird), mostly(values, weird)), max_size=20),
    new_model=any_models,
)
def test_inverse_backlash(
    model: Any,
    options: Any,
    x0: Any,
    u0: Any,
    steps: list[tuple[Any, Any]],
    new_model: Any,
) -> None:
    comp = attempt(InverseBacklash, model, options, x0, u0)
    if comp is None:
        return
    opts = comp.options
    for k, (x_d, confidence) in enumerate(steps):
        if k == len(steps) // 2:
            attempt(comp.set_model, new_model)
        u = attempt(comp.step, x_d, confidence)
        if u is not None:
            assert math.isfinite(u) and opts.u_min <= u <= opts.u_max
        state = comp.state
        assert_finite([state.x, state.u, state.u_inverse, state.offset])
    out = attempt(comp.run, [s[0] for s in steps], 1.0)
    if out is not None:
        assert_finite(out)
    attempt(comp.reset, x0, u0)


@fuzz(200)
@given(
    model=any_models,
    state=st.tuples(
        mostly(finite_values, scalars),
        mostly(finite_values, scalars),
        mostly(finite_values, scalars),
        mostly(st.integers(-1, 1), orders),
        mostly(finite_values, scalars),
        mostly(st.integers(0, 3), orders),
    ),
    x_d=scalars,
    confidence=scalars,
    options=compensator_options(),
)
def test_compensate_step(
    model: Any, state: tuple[Any, ...], x_d: Any, confidence: Any, options: Any
) -> None:
    current = attempt(CompensatorState, *state)
    if current is None:
        return
    assert_finite([current.x, current.u, current.u_inverse, current.offset])
    out = attempt(compensate_step, model, current, x_d, options, confidence)
    if out is not None:
        u, after = out
        assert math.isfinite(u)
        assert_finite([after.x, after.u, after.u_inverse, after.offset])


@fuzz(200)
@given(model=any_models, x=mostly(values, scalars), options=compensator_options())
def test_hold_interval_and_initial_state(model: Any, x: Any, options: Any) -> None:
    interval = attempt(hold_interval, model, x, options)
    if interval is not None:
        assert_finite(interval)
        assert interval[0] <= interval[1]
    state = attempt(CompensatorState.initial, model, x, None, options)
    if state is not None:
        assert_finite([state.x, state.u, state.u_inverse])


# --------------------------------------------------------------------------- examples, diagnose


@fuzz(100)
@given(
    number=orders | st.sampled_from([5, 1.0, "1"]),
    seed=st.integers(-5, 5) | st.sampled_from([2**70, 1.5, None, "0", math.nan]),
    n_samples=st.none() | orders | st.sampled_from([1, 30, -5, 1.5, "20", math.nan]),
    snr=st.none() | scalars,
)
def test_paper_examples(number: Any, seed: Any, n_samples: Any, snr: Any) -> None:
    example = attempt(paper_example, number)
    if example is None:
        return
    data = attempt(example.generate, seed, n_samples, snr)
    if data is not None:
        assert_finite(data.u)
        assert_finite(data.y)
        assert_finite(data.y_clean)
        assert math.isfinite(data.noise_std)


@fuzz(12)
@given(
    uy=pairs(600, min_size=200),
    start=st.none() | st.sampled_from([paper_example(1).model, "cubic", 3]),
    nonfinite=st.sampled_from(["raise", "drop"]),
)
def test_diagnose(uy: tuple[Any, Any], start: Any, nonfinite: str) -> None:
    u, y = uy
    result = attempt(diagnose, u, y, start=start, nonfinite=nonfinite)  # type: ignore[arg-type]
    if result is not None:
        out = result.to_dict()
        assert not math.isnan(out["gap_initial"]) and not math.isnan(out["gap_final"])
