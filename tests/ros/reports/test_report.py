"""``replay --report``: the figures a drivetrain engineer reads, with and without the truth."""

from __future__ import annotations

import dataclasses
import html
import re
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.replay import ReplayResult, replay
from genbacklash_ros.bags.simbags import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    JOINT,
    write_operation_bag,
)
from genbacklash_ros.cli.main import EXIT_OK, main
from genbacklash_ros.reports.replay import (
    branch_coverage,
    report_data,
    tracking_errors,
    write_report,
)

FIGURES = (
    "motion",
    "tracking_error",
    "play",
    "coverage",
    "characteristic",
    "convergence",
    "residuals",
    "compensation",
)


@pytest.fixture(scope="module")
def operation_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("bags") / "op"
    write_operation_bag(bag, OperationSettings(duration=8.0, wear=0.3), seed=1)
    return bag


@pytest.fixture(scope="module")
def result(operation_bag: Path, tmp_path_factory: pytest.TempPathFactory) -> ReplayResult:
    out = tmp_path_factory.mktemp("replay") / "out"
    return replay(
        operation_bag, out, command_topic=COMMAND_TOPIC, encoder_topic=ENCODER_TOPIC, joint=JOINT
    )


def _text(page: str) -> str:
    """The page's text as a browser shows it: tags dropped, entities (&#39;) decoded."""
    return " ".join(html.unescape(re.sub(r"<[^>]+>", " ", page)).split())


def test_report_with_truth(result: ReplayResult, tmp_path: Path) -> None:
    assert result.custom_data is not None  # the bag's truth came through the replay
    index = write_report(result, tmp_path / "rep")
    for name in FIGURES:
        assert (tmp_path / "rep" / f"{name}.png").stat().st_size > 10_000, name
    page = index.read_text()
    for name in FIGURES:
        assert f'src="{name}.png"' in page
    text = _text(page)
    errors = tracking_errors(result)
    assert errors is not None and errors.plant == "truth"
    none, final = errors.rms(errors.none), errors.rms(errors.final)
    assert f"RMS tracking error without compensation {none:.4g} rad" in text
    assert f"with the final estimate's inverse {final:.4g} rad" in text
    cut = 100.0 * (1.0 - final / none)
    assert f"({cut:.0f}\u00a0% cut)" in html.unescape(page)  # a no-break space
    assert "Plant: the true drivetrain stored in the bag" in text
    assert "The bag holds its truth: operation: 8 s" in text
    assert "truth at the end" in text  # the parameter table's truth column
    assert "right branch (u increasing) was engaged" in text


def test_report_without_truth(result: ReplayResult, tmp_path: Path) -> None:
    bare = dataclasses.replace(result, custom_data=None)
    index = write_report(bare, tmp_path / "rep")
    for name in FIGURES:
        assert (tmp_path / "rep" / f"{name}.png").is_file()
    text = _text(index.read_text())
    assert "Plant: the final estimate (the bag holds no truth)" in text
    assert "The bag holds no truth" in text and "truth at the end" not in text
    errors = tracking_errors(bare)
    assert errors is not None and errors.plant == "estimate"
    assert f"without compensation {errors.rms(errors.none):.4g} rad" in text


def test_predicted_error_matches_the_recording(result: ReplayResult) -> None:
    """With the true plant, the predicted uncompensated error is what the encoder saw."""
    errors = tracking_errors(result)
    assert errors is not None
    measured = float(np.sqrt(np.mean(errors.measured**2)))
    assert errors.rms(errors.none) == pytest.approx(measured, rel=0.05)
    assert measured > 0.03  # a few degrees of play: the error is the gap's size
    # the final estimate's inverse on the true plant reduces it
    assert errors.rms(errors.final) < errors.rms(errors.none)


def test_coverage_and_window(result: ReplayResult) -> None:
    data = report_data(result)
    assert data.truth is not None and data.t0_ns == data.truth.start_ns
    lo, hi = data.window
    assert 0.0 <= lo < hi <= data.end + 1e-9 and hi - lo <= 4.0
    cov = branch_coverage(data, None)
    assert cov is not None and cov.by == "final estimate"
    assert set(np.unique(cov.branch)) <= {-1, 0, 1}
    assert cov.engaged(1) is not None and cov.engaged(-1) is not None


def test_one_way_coverage_shows_one_branch(tmp_path: Path) -> None:
    bag = tmp_path / "ow"
    write_operation_bag(bag, OperationSettings(phases=(("one_way", 4.0),)), seed=0)
    res = replay(
        bag, tmp_path / "o", command_topic=COMMAND_TOPIC, encoder_topic=ENCODER_TOPIC, joint=JOINT
    )
    truth = report_data(res).truth
    assert truth is not None
    cov = branch_coverage(dataclasses.replace(report_data(res), model=None), None)
    assert cov is not None  # no estimate: the command's direction classifies
    engaged = [side for side in (1, -1) if cov.engaged(side, minimum=0.5) is not None]
    assert len(engaged) == 1


def test_replay_cli_report(operation_bag: Path, tmp_path: Path) -> None:
    rep = tmp_path / "rep"
    topics = ["--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC, "--joint", JOINT]
    args = ["replay", str(operation_bag), *topics, "-o", str(tmp_path / "o"), "--report", str(rep)]
    assert main(args) == EXIT_OK
    assert "RMS tracking error" in (rep / "index.html").read_text()


def test_the_report_says_when_compensation_was_on_faded_or_off_and_why() -> None:
    """Issue 23: the replay report shows the compensation's state over the record with the
    node's reasons (a stretch holds from its report to the next)."""
    from types import SimpleNamespace

    from genbacklash_ros.bags.replay import ReplayHistory
    from genbacklash_ros.node.compensate import CompensationStatus
    from genbacklash_ros.reports.replay import compensation_section, compensation_spans

    history = ReplayHistory(
        compensation_t=[0, 1_000_000_000, 2_000_000_000, 3_000_000_000],
        compensation=[
            CompensationStatus(0.0, "off", "no estimate yet"),
            CompensationStatus(1.0, "on", "compensation on: the model leaves 4 %"),
            CompensationStatus(0.4, "faded", "compensation faded to 40 %: the model leaves 87 %"),
            CompensationStatus(0.4, "faded", "compensation faded to 41 %: the model leaves 86 %"),
        ],
    )
    result = SimpleNamespace(history=history)
    spans = compensation_spans(result)  # type: ignore[arg-type]
    assert [(a, b, s) for a, b, s, _ in spans] == [
        (0.0, 1.0, "off"),
        (1.0, 2.0, "on"),
        (2.0, 3.0, "faded"),
    ]
    section = compensation_section(result)  # type: ignore[arg-type]
    assert "on 33 % of the time, faded 33 % and off 33 %" in section.paragraphs[0]
    assert section.tables[0].rows[2][3].startswith("compensation faded to 40 %")
