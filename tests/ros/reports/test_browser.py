"""Every report page opened in a headless browser (Debian's chromium): the rendered text
shows no raw Markdown and no escaped entities, and every image loads.

The page is copied beside itself (so that its relative image paths resolve) with a script
that runs on the window's load event and writes, into the DOM, the number of images, those
that did not load (``naturalWidth == 0``) and ``document.body.innerText``;
``chromium --headless --dump-dom`` prints that DOM. A screenshot of the page itself is taken
too. Skipped, with the reason, only when no chromium binary is found.
"""

from __future__ import annotations

import html
import json
import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from genbacklash_core.diagnose import synthetic_case
from genbacklash_core.scenarios import OperationSettings
from genbacklash_ros.bags.csvio import Series, write_series_csv
from genbacklash_ros.bags.simbags import COMMAND_TOPIC, ENCODER_TOPIC, write_operation_bag
from genbacklash_ros.cli.main import EXIT_OK, main
from genbacklash_ros.fleet.report import write_fleet_report
from genbacklash_ros.fleet.summary import summarise
from tests.ros.fleet.test_report import _rows, fleet_summary

_NAMES = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")
_CHECK = """<script>
window.addEventListener("load", function () {
  var images = Array.from(document.images);
  var out = document.createElement("pre");
  out.id = "browser-check";
  out.textContent = JSON.stringify({
    images: images.length,
    broken: images
      .filter(function (i) { return !(i.complete && i.naturalWidth > 0); })
      .map(function (i) { return i.getAttribute("src"); }),
    text: document.body.innerText
  });
  document.body.appendChild(out);
});
</script>
"""
_ENTITY = re.compile(r"&(?:[A-Za-z]+|#[0-9]+|#x[0-9A-Fa-f]+);")


def _chromium() -> str:
    explicit = os.environ.get("GENBACKLASH_CHROMIUM")
    found = explicit or next((p for p in map(shutil.which, _NAMES) if p), None)
    if not found:
        pytest.skip(
            f"no chromium binary found (looked for {', '.join(_NAMES)} on PATH and "
            "$GENBACKLASH_CHROMIUM); on Debian: apt-get install -y chromium"
        )
    return found


def _run(browser: str, profile: Path, *args: str) -> str:
    command = [
        browser,
        "--headless",
        "--no-sandbox",  # CI runs as root
        "--disable-gpu",
        "--disable-dev-shm-usage",
        "--hide-scrollbars",
        f"--user-data-dir={profile}",
        *args,
    ]
    done = subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def _probe(browser: str, index: Path, profile: Path) -> dict[str, object]:
    """Open a copy of ``index`` with the check script; what the browser found."""
    probe = index.with_name("_browser_check.html")
    page = index.read_text(encoding="utf-8")
    assert "</body>" in page
    probe.write_text(page.replace("</body>", _CHECK + "</body>"), encoding="utf-8")
    try:
        dom = _run(browser, profile, "--dump-dom", probe.as_uri())
    finally:
        probe.unlink()
    found = re.search(r'<pre id="browser-check">(.*?)</pre>', dom, re.S)
    assert found, f"the check script did not run; DOM starts {dom[:300]!r}"
    result: dict[str, object] = json.loads(html.unescape(found.group(1)))
    return result


def open_in_browser(index: Path, tmp_path: Path) -> dict[str, object]:
    """What the browser shows of ``index``: ``images``, ``broken`` (their src), ``text``;
    and a screenshot of it at ``tmp_path / (index's folder name + '.png')``."""
    browser = _chromium()
    shown = _probe(browser, index, tmp_path / "profile")
    shot = tmp_path / f"{index.parent.name}.png"
    _run(browser, tmp_path / "profile", f"--screenshot={shot}", "--window-size=1280,2400",
         index.as_uri())  # fmt: skip
    assert shot.read_bytes()[:4] == b"\x89PNG" and shot.stat().st_size > 10_000
    return shown


def _assert_readable(shown: dict[str, object], images: int) -> None:
    text = str(shown["text"])
    assert shown["broken"] == [], f"images that did not load: {shown['broken']}"
    assert shown["images"] == images
    for raw in ("|---|", "**", "| # |", "```"):  # Markdown shown as text
        assert raw not in text, raw
    assert not _ENTITY.search(text), _ENTITY.findall(text)  # escaped twice: &ndash; as text
    assert "Summary" in text  # the shared layout's summary block
    # one word for each thing: play (c_L + c_R) and misfit (NRMSE); gap_drift is a name
    assert not re.search(r"\bgap\b", text, re.IGNORECASE), re.findall(r".{30}\bgap\b.{30}", text)


def test_replay_report_in_a_browser(tmp_path: Path) -> None:
    _chromium()
    bag = tmp_path / "op"
    write_operation_bag(bag, OperationSettings(duration=6.0, wear=0.3), seed=1)
    report = tmp_path / "replay"
    args = ["replay", str(bag), "--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC]
    args += ["--joint", "drive_joint"]  # the bag's JointState carries two joints
    assert main([*args, "-o", str(tmp_path / "o"), "--report", str(report), "--no-progress"]) == 0
    shown = open_in_browser(report / "index.html", tmp_path)
    _assert_readable(shown, images=9)  # 9 figures: compensation_state.png too
    assert "RMS tracking error without compensation" in str(shown["text"])


def test_diagnose_report_in_a_browser(tmp_path: Path) -> None:
    _chromium()
    case = synthetic_case(["gap_drift"], 42, 1500)
    data = tmp_path / "drift.csv"
    write_series_csv(data, Series(case.u, case.y))
    report = tmp_path / "diagnose"
    assert main(["diagnose", str(data), "--report", str(report)]) == EXIT_OK
    shown = open_in_browser(report / "index.html", tmp_path)
    _assert_readable(shown, images=6)
    text = str(shown["text"])
    assert "gap_drift" in text and "Detectors per round" in text


def test_fleet_report_in_a_browser(tmp_path: Path) -> None:
    _chromium()
    index = write_fleet_report(fleet_summary(), tmp_path / "fleet")
    shown = open_in_browser(index, tmp_path)
    _assert_readable(shown, images=5)  # fleet.png and one per drivetrain
    assert "<noisy>" in str(shown["text"])  # escaped in the HTML, shown as written


def test_fleet_report_with_a_truncated_bag_in_a_browser(tmp_path: Path) -> None:
    """A bag cut part-way shows its flag in the ranking, a table and the summary."""
    _chromium()
    rows = _rows("cut & short", 0.10, 0.004)
    rows[3].truncated, rows[3].duration_s, rows[3].recorded_s = True, 4.46, 10.0
    index = write_fleet_report(summarise(rows, gap_limit=0.15), tmp_path / "cut")
    shown = open_in_browser(index, tmp_path)
    _assert_readable(shown, images=2)
    text = str(shown["text"])
    assert "Truncated bags" in text and "truncated: read 4.5 of 10.0 s" in text


def test_the_check_sees_a_broken_image_and_an_entity(tmp_path: Path) -> None:
    """The probe itself: a missing PNG and a doubly escaped dash are caught."""
    folder = tmp_path / "bad"
    folder.mkdir()
    index = folder / "index.html"
    index.write_text(
        "<!DOCTYPE html><html><body><h1>Summary</h1><p>a &amp;ndash; b **c**</p>"
        '<img src="missing.png"></body></html>',
        encoding="utf-8",
    )
    shown = _probe(_chromium(), index, tmp_path / "profile")
    assert shown["broken"] == ["missing.png"]
    assert _ENTITY.search(str(shown["text"])) and "**" in str(shown["text"])
