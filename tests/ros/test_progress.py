"""The progress line: a bar on a terminal, plain rate-limited lines without one."""

from __future__ import annotations

import io
import time

from genbacklash_ros.progress import Progress


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_plain_lines_without_a_terminal() -> None:
    stream = io.StringIO()
    with Progress("genbacklash test", total=10, unit="bag", every=0.05, stream=stream) as bar:
        bar.set_stage("round 1")
        bar.update(3)
        time.sleep(0.3)
    lines = stream.getvalue().splitlines()
    assert 2 <= len(lines) <= 8  # about one per 0.05 s, and the last
    assert lines[0].startswith("genbacklash test: round 1; 3/10 bags (30%), ")
    assert lines[-1].startswith("genbacklash test: done (3/10 bags (30%), ")
    assert "\r" not in stream.getvalue()  # no carriage returns in a log


def test_without_a_stage_or_total() -> None:
    stream = io.StringIO()
    with Progress("genbacklash fleet", total=40, unit="bag", every=0.05, stream=stream):
        time.sleep(0.12)
    assert stream.getvalue().splitlines()[0].startswith("genbacklash fleet: 0/40 bags (0%), ")
    assert Progress("x", enabled=False).line().startswith("x: 0 s")


def test_short_work_and_disabled_print_nothing() -> None:
    stream = io.StringIO()
    with Progress("quick", every=5.0, stream=stream) as bar:
        bar.update(1)
    with Progress("off", every=0.01, enabled=False, stream=stream) as bar:
        bar.update(1)
        time.sleep(0.05)
    assert stream.getvalue() == ""


def test_a_bar_on_a_terminal() -> None:
    stream = _Terminal()
    with Progress("genbacklash test", total=4, unit="msg", stream=stream) as bar:
        bar.set_stage("reading")
        bar.update(2)
        time.sleep(1.3)  # the ticker redraws the bar every second, also while a step runs
    shown = stream.getvalue()
    assert "genbacklash test" in shown and "2/4" in shown and "reading" in shown


def test_an_error_says_stopped() -> None:
    stream = io.StringIO()
    try:
        with Progress("genbacklash test", every=0.05, stream=stream):
            time.sleep(0.08)
            raise ValueError("bad input")
    except ValueError:
        pass
    assert stream.getvalue().splitlines()[-1].startswith("genbacklash test: stopped (")
