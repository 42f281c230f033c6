"""Bad data and bad options: clear errors, or a non-converged result that says why."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import genbacklash_core
from genbacklash_core import (
    Cascade,
    GenBacklashError,
    GeneralBacklash,
    IdentificationResult,
    NonFiniteInputError,
    NotEnoughExcitationError,
    count_reversals,
    identify_backlash,
    identify_cascade,
    paper_example,
    prepare_series,
    refine_output_error,
)
from genbacklash_core.structure import Structure

from ._helpers import TOL_PAPER

CORE_DIR = Path(genbacklash_core.__file__).parent
BANNED = {"rclpy", "rosbags", "mcap", "cyclonedds", "matplotlib", "genbacklash_ros"}


def _example_data(number: int = 1, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    data = paper_example(number).generate(seed)
    return data.u.copy(), data.y.copy()


def _identify(kind: str, u: np.ndarray, y: np.ndarray, **options: object) -> IdentificationResult:
    if kind == "backlash":
        return identify_backlash(u, y, 3, **options)  # type: ignore[arg-type]
    return identify_cascade(u, y, 3, 2, 2, **options)  # type: ignore[arg-type]


# --------------------------------------------------------------------------- non-finite samples


@pytest.mark.parametrize("kind", ["backlash", "cascade"])
def test_nan_in_u_names_count_and_indices(kind: str) -> None:
    u, y = _example_data(1 if kind == "backlash" else 3)
    u[[3, 17]] = np.nan
    with pytest.raises(
        NonFiniteInputError,
        match=rf"^2 of {u.size} samples are NaN or infinite \(u: 2, y: 0\), at index 3, 17; ",
    ):
        _identify(kind, u, y)


def test_inf_in_y_names_count_and_index() -> None:
    u, y = _example_data()
    y[500] = np.inf
    y[0] = -np.inf
    with pytest.raises(
        NonFiniteInputError,
        match=r"^2 of 800 samples are NaN or infinite \(u: 0, y: 2\), at index 0, 500; .*"
        r"nonfinite='drop'",
    ):
        identify_backlash(u, y, 3)


def test_bad_in_both_counted_once_per_sample() -> None:
    u, y = _example_data()
    u[[5, 9]] = np.nan
    y[[9, 700]] = np.nan
    with pytest.raises(
        NonFiniteInputError,
        match=r"^3 of 800 samples .*\(u: 2, y: 2\), at index 5, 9, 700;",
    ):
        identify_backlash(u, y, 3)


def test_many_bad_samples_are_summarised() -> None:
    u, y = _example_data()
    u[100:107] = np.nan
    with pytest.raises(
        NonFiniteInputError, match=r"^7 of 800 .*at index 100, 101, 102, 103, 104 and 2 more;"
    ):
        identify_backlash(u, y, 3)


def test_nonfinite_error_is_a_genbacklash_error() -> None:
    with pytest.raises(GenBacklashError, match="NaN or infinite"):
        prepare_series([0.0, float("nan")], [1.0, 2.0])


def test_drop_removes_the_bad_samples() -> None:
    u = np.array([0.0, np.nan, 2.0, 3.0, 4.0])
    y = np.array([0.0, 1.0, np.inf, 3.0, 4.0])
    uu, yy = prepare_series(u, y, "drop")
    np.testing.assert_array_equal(uu, [0.0, 3.0, 4.0])
    np.testing.assert_array_equal(yy, [0.0, 3.0, 4.0])


def test_drop_identifies_through_the_gaps() -> None:
    ex = paper_example(1)
    u, y = _example_data(1, 2)
    bad = np.random.default_rng(0).choice(u.size, 12, replace=False)
    u[bad[:6]] = np.nan
    y[bad[6:]] = np.inf
    result = identify_backlash(u, y, 3, nonfinite="drop")
    assert result.converged, result.reason
    assert np.max(np.abs(result.model.parameters() - ex.model.parameters())) < TOL_PAPER
    with pytest.raises(NonFiniteInputError, match="12 of 800 samples"):
        identify_backlash(u, y, 3)


def test_invalid_nonfinite_policy_with_bad_data() -> None:
    u, y = _example_data()
    u[3] = np.nan
    with pytest.raises(GenBacklashError, match=r"nonfinite must be 'raise' or 'drop', got 'skip'"):
        identify_backlash(u, y, 3, nonfinite="skip")  # type: ignore[arg-type]


def test_invalid_nonfinite_policy_with_clean_data() -> None:
    u, y = _example_data()
    with pytest.raises(GenBacklashError, match=r"nonfinite must be 'raise' or 'drop'"):
        identify_backlash(u, y, 3, nonfinite="skip")  # type: ignore[arg-type]


# --------------------------------------------------------------------------- excitation


@pytest.mark.parametrize(
    ("kind", "n", "message"),
    [
        ("backlash", 10, r"not enough excitation: 10 samples for 8 parameters; need at least 40"),
        ("backlash", 39, r"not enough excitation: 39 samples for 8 parameters"),
        ("cascade", 54, r"not enough excitation: 54 samples for 11 parameters; need at least 55"),
        ("cascade", 0, r"not enough excitation: 0 samples"),
    ],
)
def test_too_short(kind: str, n: int, message: str) -> None:
    u, y = _example_data(1 if kind == "backlash" else 3)
    with pytest.raises(NotEnoughExcitationError, match=message):
        _identify(kind, u[:n], y[:n])


def test_degree1_needs_at_least_20_samples() -> None:
    u, y = _example_data()
    with pytest.raises(
        NotEnoughExcitationError, match="19 samples for 4 parameters; need at least 20"
    ):
        identify_backlash(u[:19], y[:19], 1)


@pytest.mark.parametrize("kind", ["backlash", "cascade"])
def test_constant_input(kind: str) -> None:
    _, y = _example_data()
    with pytest.raises(NotEnoughExcitationError, match=r"the input is constant \(0.3\)"):
        _identify(kind, np.full(800, 0.3), y)


@pytest.mark.parametrize(
    ("u", "reversals"),
    [
        (np.linspace(-1, 1, 200), 0),
        (np.concatenate([np.linspace(-1, 1, 100), np.linspace(1, -1, 100)]), 1),
        (np.repeat(np.linspace(2, -2, 50), 4), 0),  # monotone with flat steps
    ],
    ids=["ramp", "one-reversal", "staircase"],
)
@pytest.mark.parametrize("kind", ["backlash", "cascade"])
def test_input_without_two_reversals(kind: str, u: np.ndarray, reversals: int) -> None:
    y = np.sin(np.arange(u.size))
    with pytest.raises(
        NotEnoughExcitationError, match=rf"reverses direction {reversals} time\(s\)"
    ):
        _identify(kind, u, y)


def test_constant_output() -> None:
    u, _ = _example_data()
    with pytest.raises(NotEnoughExcitationError, match="the output never changes"):
        identify_backlash(u, np.full(u.size, 1.5), 3)


def test_count_reversals() -> None:
    assert count_reversals(np.array([0.0, 1.0, 1.0, 2.0, 1.0, 1.0, 0.0, 3.0])) == 2
    assert count_reversals(np.array([0.0, 0.0, 0.0])) == 0
    assert count_reversals(np.array([1.0])) == 0


# --------------------------------------------------------------------------- shapes and options


@pytest.mark.parametrize("kind", ["backlash", "cascade"])
def test_mismatched_lengths(kind: str) -> None:
    u, y = _example_data()
    with pytest.raises(GenBacklashError, match="same length, got 800 and 799"):
        _identify(kind, u, y[:-1])


@pytest.mark.parametrize("kind", ["backlash", "cascade"])
def test_two_dimensional_input(kind: str) -> None:
    u, y = _example_data()
    with pytest.raises(GenBacklashError, match=r"one-dimensional, got shapes \(400, 2\)"):
        _identify(kind, u.reshape(400, 2), y.reshape(400, 2))
    with pytest.raises(GenBacklashError, match=r"one-dimensional, got shapes \(800,\), \(800, 1\)"):
        _identify(kind, u, y[:, None])


@pytest.mark.parametrize("degree", [0, -1])
def test_invalid_degree(degree: int) -> None:
    u, y = _example_data(3)
    with pytest.raises(GenBacklashError, match=rf"degree must be >= 1, got {degree}"):
        identify_backlash(u, y, degree)
    with pytest.raises(GenBacklashError, match=rf"degree must be >= 1, got {degree}"):
        identify_cascade(u, y, degree, 2, 2)


@pytest.mark.parametrize(("na", "nb"), [(0, 2), (-1, 0), (2, -1), (0, 0)])
def test_invalid_orders(na: int, nb: int) -> None:
    u, y = _example_data(3)
    with pytest.raises(GenBacklashError, match=rf"need na >= 1 and nb >= 0, got na={na}, nb={nb}"):
        identify_cascade(u, y, 3, na, nb)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"degree": 0}, "degree must be >= 1"),
        ({"degree": 2, "na": -1}, "na and nb must be >= 0"),
        ({"degree": 2, "na": 0, "nb": 1}, r"a linear block needs na >= 1"),
        ({"degree": 2, "sign": 0.5}, r"sign must be \+1 or -1"),
    ],
)
def test_invalid_structure(kwargs: dict[str, float], message: str) -> None:
    with pytest.raises(GenBacklashError, match=message):
        Structure(**kwargs)  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("degree", "na", "nb"), [(2.5, 2, 2), (3.0, 2, 2), (3, 1.5, 2), (3, 2, 1.5)]
)
def test_non_integer_orders_raise_genbacklash_error(degree: float, na: float, nb: float) -> None:
    u, y = _example_data(3)
    with pytest.raises(GenBacklashError, match=r"(degree|na|nb)"):
        identify_cascade(u, y, degree, na, nb)  # type: ignore[arg-type]


def test_numpy_integer_orders_are_accepted() -> None:
    u, y = _example_data(3)
    result = identify_cascade(u, y, np.int64(3), np.int64(2), np.int64(2))  # type: ignore[arg-type]
    assert result.converged, result.reason


# --------------------------------------------------------------------------- wrong structure


def _case(kind: str, delay: int, seed: int) -> object:
    return pytest.param(kind, delay, seed, id=f"{kind}-{delay}-seed{seed}")


def _assert_failed_cleanly(result: IdentificationResult) -> None:
    assert result.converged is False, result.reason
    assert isinstance(result.reason, str)
    assert result.reason.strip()
    assert np.all(np.isfinite(result.model.parameters()))
    assert np.all(np.isfinite(result.equation_error_model.parameters()))
    assert not np.isnan(result.fit.nrmse)
    out = result.to_dict()
    assert out["converged"] is False
    assert out["reason"] == result.reason


@pytest.mark.parametrize(
    ("kind", "delay", "seed"),
    [_case("cascade-delay", d, s) for d in (3, 4, 5) for s in range(4)],
)
def test_extra_delay_is_reported_not_raised(kind: str, delay: int, seed: int) -> None:
    data = paper_example(3).generate(seed)
    u, y = data.u[:-delay], data.y[delay:]  # y(t) now depends on u(t - 1 - delay)
    result = identify_cascade(u, y, 3, 2, 2)
    _assert_failed_cleanly(result)


@pytest.mark.parametrize(
    ("kind", "delay", "seed"),
    [
        _case(k, d, s)
        for k in ("backlash-pure-delay", "cascade-pure-delay")
        for d in (1, 2, 5)
        for s in range(4)
    ],
)
def test_pure_delay_is_reported_not_raised(kind: str, delay: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1, 1, 1000)
    y = np.concatenate([np.zeros(delay), u[:-delay]])  # no dead zone at all
    result = (
        identify_backlash(u, y, 3)
        if kind.startswith("backlash")
        else identify_cascade(u, y, 3, 2, 2)
    )
    _assert_failed_cleanly(result)


def test_wrong_sign_is_reported_not_raised() -> None:
    u, y = _example_data(1)
    result = identify_backlash(u, y, 3, sign=-1)  # the branches really increase
    _assert_failed_cleanly(result)


# --------------------------------------------------------------------------- refinement


def test_refine_backlash_from_rough_start_moves_closer() -> None:
    ex = paper_example(1)
    data = ex.generate(1)
    rough = GeneralBacklash((0.45, -0.25, 0.3), 0.6, (0.55, 0.4, 0.2), 0.7)
    out = refine_output_error(rough, data.u, data.y)
    before = np.max(np.abs(rough.parameters() - ex.model.parameters()))
    after = np.max(np.abs(out.model.parameters() - ex.model.parameters()))
    assert after < 0.3 * before
    assert after < TOL_PAPER
    assert out.cost_end < out.cost_start
    assert out.iterations >= 1


def test_refine_cascade_from_rough_start_moves_closer() -> None:
    ex = paper_example(3)
    assert isinstance(ex.model, Cascade)
    data = ex.generate(2)
    offset = np.array([0.05, -0.05, -0.05, 0.05, -0.05, 0.05, 0.05, 0.05, 0.03, 0.03, 0.03])
    rough = Cascade.from_parameters(ex.model.parameters() + offset, 3, 2, 2)
    assert rough.backlash.branches_separated(-1.0, 1.0)  # a valid start on the data range
    out = refine_output_error(rough, data.u, data.y)
    after = np.max(np.abs(out.model.parameters() - ex.model.parameters()))
    assert after < 0.3 * 0.05
    assert out.cost_end < 0.1 * out.cost_start
    assert isinstance(out.model, Cascade)


def test_refine_rejects_invalid_start() -> None:
    # a start the refinement may not leave: the flat vector must be a valid model
    from genbacklash_core.refine import refine_parameters

    u, y = _example_data()
    with pytest.raises(GenBacklashError, match="cannot refine from an invalid model"):
        refine_parameters(Structure(3), np.zeros(8), u, y, 0.0)


# --------------------------------------------------------------------------- import hygiene


def _imported_top_level_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.add(node.module.split(".")[0])
    return found


def test_core_sources_import_no_ros_io_or_plotting() -> None:
    sources = sorted(CORE_DIR.glob("*.py"))
    assert len(sources) >= 10
    third_party: set[str] = set()
    for path in sources:
        modules = _imported_top_level_modules(path)
        assert not modules & BANNED, (path.name, modules & BANNED)
        third_party |= {m for m in modules if m not in sys.stdlib_module_names}
    assert third_party == {"numpy", "scipy"}


def test_importing_the_core_loads_no_banned_module() -> None:
    code = (
        "import sys, genbacklash_core\n"
        f"print(sorted(m for m in {sorted(BANNED)!r} if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=60
    )
    assert out.stdout.strip() == "[]"
