"""The live demo's verdict (genbacklash_ros/demo/verdict.py): harm is called beyond the spread
of the comparison itself, and a worse number within it is explained, never hidden."""

from __future__ import annotations

import math

import pytest

from genbacklash_ros.demo.live import LiveResult, _table
from genbacklash_ros.demo.verdict import HARM, Comparison, DemoVerdict

NONE = Comparison(math.nan, math.nan, math.nan, 0.0)


@pytest.mark.parametrize(
    ("arm", "perturbed", "harmful"),
    [
        (0.0298, 0.0301, False),  # -7.2 % with twins 8.3 % apart: the spread
        (0.0298, 0.0280, True),  # -7.2 % with twins 0.7 % apart: harm
        (0.0278 * (1 + HARM) - 1e-6, 0.0278, False),  # within the first rule's margin
        (0.0200, 0.0330, False),  # better
    ],
)
def test_harm_is_a_cut_below_the_margin_and_the_spread(
    arm: float, perturbed: float, harmful: bool
) -> None:
    comparison = Comparison(arm, 0.0278, perturbed, 20.0)
    assert comparison.harmful is harmful
    assert comparison.cut == pytest.approx(1 - arm / 0.0278)
    assert comparison.spread == pytest.approx(abs(1 - perturbed / 0.0278))


def test_no_readings_judge_nothing() -> None:
    assert math.isnan(NONE.cut) and math.isnan(NONE.spread) and not NONE.harmful
    assert DemoVerdict(Comparison(0.01, 0.03, 0.03, 20.0), NONE).explain("j") is None


def test_harm_where_compensation_acted_is_harm_whatever_the_half_says() -> None:
    """A trial that tracked 20 % worse over its 3 s, twins 1 % apart there, is harm even
    when the second half reads within the spread."""
    half = Comparison(0.0285, 0.0280, 0.0290, 20.0)
    acted = Comparison(0.036, 0.030, 0.0303, 3.0)
    verdict = DemoVerdict(half, acted)
    assert verdict.worse
    line = verdict.explain("joint_2")
    assert line is not None and line.startswith("WARNING: compensation made tracking worse")
    assert "3.0 s of readings" in line and "-20.0 %" in line


def _result(arm: float, twin: float, verdict: DemoVerdict) -> LiveResult:
    return LiveResult(
        ("joint_1",), 0.0698, (0.0556,), (arm,), (twin,), ("off",), 4000, 4000, 0.0, (verdict,)
    )


def test_the_table_explains_a_worse_cut_within_the_spread_and_warns_beyond_it() -> None:
    """The -7 % run of 2026-11-28 (seed 1, 1 kHz): compensation off for all but 2 s of the
    second half. The table still prints the cut, and says why it is not harm; the same cut
    with twins that agree is harm."""
    lines: list[str] = []
    within = DemoVerdict(Comparison(0.0298, 0.0278, 0.0301, 20.0), NONE)
    _table(_result(0.0298, 0.0278, within), lines.append)
    text = "\n".join(lines)
    assert "-7%" in text  # the plain cut, as before
    assert "WARNING" not in text
    assert "note: joint_1 tracked 7.2 % worse than its twin" in text and "8.3 %" in text
    lines.clear()
    beyond = DemoVerdict(Comparison(0.0298, 0.0278, 0.0279, 20.0), NONE)
    _table(_result(0.0298, 0.0278, beyond), lines.append)
    assert "WARNING: compensation made tracking worse on joint_1" in "\n".join(lines)
