"""Restart: kill -9 the DDS node mid-run, restart it, measure how it resumes (issue 6).

    python bench/restart.py [--quick]

The measurement is the real multi-process run of ``tests/ros/transports/test_restart.py`` (a player
process at 500 Hz, the node as its own process over DDS with a checkpoint every 2 s of data
time, SIGKILL mid-run, a restart with the same parameters; plus a checkpoint writer SIGKILLed
repeatedly mid-save). This script runs that test module once with ``pytest -s``, so the
numbers below are the ones its assertions were checked on, and reports what it printed
(``--quick`` changes nothing: the run takes about 40 s either way).
"""

from __future__ import annotations

import subprocess
import sys
import time

from _common import ROOT, command_line, machine_description, parse_args, write_section


def main() -> None:
    parse_args(__doc__.splitlines()[0], sys.argv[1:])
    machine = machine_description()
    started = time.perf_counter()
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "pytest",
            "-s",
            "-p",
            "no:cacheprovider",
            "-rs",
            "tests/ros/transports/test_restart.py",
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        check=False,
    )
    seconds = time.perf_counter() - started
    lines = proc.stdout.splitlines()
    measured = [line.strip() for line in lines if "restart:" in line or "kills;" in line]
    summary = next((line for line in reversed(lines) if " passed" in line or "failed" in line), "")
    verdict = "met" if proc.returncode == 0 else "NOT met (see the test output)"
    bullets = "\n".join(f"* {line.lstrip('. ')}" for line in measured) or "* (nothing printed)"
    text = f"""## Restart (issue 6)

`{command_line()}`. Machine: {machine}. Run time {seconds:.0f} s.

`pytest -s tests/ros/transports/test_restart.py`: {summary.strip(" =")}. The DDS
node (its own process, checkpoint every 2 s of data time) is SIGKILLed mid-run while a player
process publishes command and encoder at 500 Hz, then restarted with the same parameters; a
checkpoint writer is SIGKILLed repeatedly mid-save. What the run measured:

{bullets}

Target - restart resumes within one checkpoint period (2 s), from a checkpoint that is never
half-written: **{verdict}**.
"""
    write_section("restart", text)
    print(text)
    if proc.returncode != 0:
        print(proc.stdout[-4000:], file=sys.stderr)


if __name__ == "__main__":
    main()
