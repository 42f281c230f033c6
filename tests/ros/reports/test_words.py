"""One word for each thing (issue 22, deliverable 4): the replay, diagnose and fleet pages say
"play" for c_L + c_R and "misfit" for the NRMSE, never "gap" -- in the page's text and in
the text drawn in its figures (titles, labels, legends, notes). Effect names such as
``gap_drift`` are fixed names, not the word."""

from __future__ import annotations

import html
import re
from pathlib import Path
from typing import Any

import matplotlib.figure
import pytest
from matplotlib.text import Text

from genbacklash_core.diagnose import synthetic_case
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.csvio import Series, write_series_csv
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, write_operation_bag
from genbacklash_ros.cli.main import EXIT_OK, main
from genbacklash_ros.fleet.report import write_fleet_report
from genbacklash_ros.fleet.summary import summarise
from tests.ros.fleet.test_report import _rows

GAP = re.compile(r"\bgap\b", re.IGNORECASE)  # gap_drift (an effect's fixed name) is no match


def visible_text(page: str) -> str:
    """What a browser shows of an HTML page: the text outside tags, styles and scripts."""
    body = re.sub(r"<(style|script)\b.*?</\1>", " ", page, flags=re.S | re.I)
    return html.unescape(re.sub(r"<[^>]+>", " ", body))


@pytest.fixture
def drawn(monkeypatch: pytest.MonkeyPatch) -> list[str]:
    """Every text drawn in the figures saved while the test runs."""
    texts: list[str] = []
    original = matplotlib.figure.Figure.savefig

    def savefig(self: matplotlib.figure.Figure, *args: Any, **kwargs: Any) -> None:
        texts.extend(t.get_text() for t in self.findobj(Text))
        original(self, *args, **kwargs)

    monkeypatch.setattr(matplotlib.figure.Figure, "savefig", savefig)
    return texts


def _no_gap(text: str, where: str) -> None:
    found = [line.strip() for line in text.splitlines() if GAP.search(line)]
    assert not found, f"'gap' in {where}: {found[:5]}"


def test_the_word_is_caught() -> None:
    assert GAP.search("the Gap limit") and GAP.search("gap.") and not GAP.search("gap_drift")


def test_the_replay_page_and_its_figures(tmp_path: Path, drawn: list[str]) -> None:
    bag = tmp_path / "op"
    write_operation_bag(bag, OperationSettings(duration=6.0, wear=0.3), seed=1)
    args = ["replay", str(bag), "--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC]
    args += ["--joint", "drive_joint", "-o", str(tmp_path / "o"), "--no-progress"]
    assert main([*args, "--report", str(tmp_path / "rep")]) == 0
    page = (tmp_path / "rep" / "index.html").read_text(encoding="utf-8")
    assert "Play" in visible_text(page) or "play" in visible_text(page)
    _no_gap(visible_text(page), "the replay page")
    assert len(drawn) > 20
    _no_gap("\n".join(drawn), "the replay figures")
    assert not list((tmp_path / "rep").glob("*gap*"))  # nor a file named for it


def test_the_diagnose_page_and_its_figures(tmp_path: Path, drawn: list[str]) -> None:
    case = synthetic_case(["gap_drift"], 42, 1500)
    data = tmp_path / "drift.csv"
    write_series_csv(data, Series(case.u, case.y))
    assert main(["diagnose", str(data), "--report", str(tmp_path / "rep")]) == EXIT_OK
    page = (tmp_path / "rep" / "index.html").read_text(encoding="utf-8")
    assert "gap_drift" in visible_text(page)  # the effect's name stays
    _no_gap(visible_text(page), "the diagnose page")
    _no_gap((tmp_path / "rep" / "summary.md").read_text(encoding="utf-8"), "summary.md")
    _no_gap("\n".join(drawn), "the diagnose figures")
    assert not list((tmp_path / "rep").glob("*gap*"))


def test_the_fleet_page_and_its_figures(tmp_path: Path, drawn: list[str]) -> None:
    rows = _rows("fast", 0.10, 0.004) + _rows("flat", 0.10, -0.002)  # one that does not wear
    index = write_fleet_report(summarise(rows, gap_limit=0.15), tmp_path / "fleet")
    text = visible_text(index.read_text(encoding="utf-8"))
    assert "Play limit" in text and "the play does not grow" in text
    _no_gap(text, "the fleet page")
    _no_gap("\n".join(drawn), "the fleet figures")
