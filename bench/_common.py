"""Helpers shared by the benchmark scripts: timing, machine description, markdown output.

Timing follows :mod:`timeit`: a call that takes less than ``MIN_REPEAT_TIME`` is repeated
``number`` times per measurement and the mean per call is taken; the reported time is the best
(minimum) of ``k`` such measurements, which is the least disturbed by other load on the machine.
When several functions are compared they are measured round-robin, so a burst of load from
another process hits all of them alike and the ratios stay meaningful.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import io
import json
import math
import os
import platform
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import scipy

BENCH_DIR = Path(__file__).resolve().parent
ROOT = BENCH_DIR.parent
OUTPUT_DIR = BENCH_DIR / "output"
MIN_REPEAT_TIME = 0.02  # seconds; shorter calls are repeated within one measurement

__all__ = [
    "BENCH_DIR",
    "OUTPUT_DIR",
    "ROOT",
    "Timing",
    "command_line",
    "fmt_bytes",
    "fmt_ratio",
    "fmt_time",
    "machine_description",
    "md_table",
    "parse_args",
    "time_interleaved",
    "write_section",
]


def parse_args(description: str, argv: Sequence[str] | None = None) -> argparse.Namespace:
    """The common command line: ``--quick`` for smaller settings."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--quick", action="store_true", help="smaller settings (smoke test)")
    return parser.parse_args(argv)


def cpu_model() -> str:
    """CPU model name from /proc/cpuinfo (Linux), else ``platform.processor()``."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as handle:
            for line in handle:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


def load_average() -> str:
    """1-minute load average, or ``n/a``."""
    try:
        return f"{os.getloadavg()[0]:.2f}"
    except (AttributeError, OSError):
        return "n/a"


def machine_description() -> str:
    """One sentence naming the machine and the library versions."""
    return (
        f"`{platform.platform()}`, {cpu_model()}, {os.cpu_count()} logical cores (shared: "
        f"another developer's test runs may execute at the same time; 1-min load average "
        f"{load_average()} when the script started), Python {platform.python_version()}, "
        f"numpy {np.__version__}, scipy {scipy.__version__}"
    )


def command_line() -> str:
    """The command that produced the current script's tables, e.g. ``python bench/kernel.py``."""
    return " ".join(["python", f"bench/{Path(sys.argv[0]).name}", *sys.argv[1:]])


@dataclass(frozen=True)
class Timing:
    """Best per-call time [s] of ``runs`` measurements of ``number`` calls each."""

    best: float
    runs: int
    number: int

    @property
    def label(self) -> str:
        """``best of k`` (``x n calls`` when calls were batched)."""
        calls = f" x {self.number} calls" if self.number > 1 else ""
        return f"best of {self.runs}{calls}" if self.runs > 1 else f"1 run{calls}"


def _measure(fn: Callable[[], object], number: int) -> float:
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        start = time.perf_counter()
        for _ in range(number):
            fn()
        return (time.perf_counter() - start) / number
    finally:
        if was_enabled:
            gc.enable()


def time_interleaved(
    functions: dict[str, Callable[[], object]], repeats: dict[str, int] | int = 3
) -> dict[str, Timing]:
    """Best-of-k per-call times of several functions, measured round-robin.

    The first (calibration) call of a function counts as one run when it takes at least
    ``MIN_REPEAT_TIME``; faster functions are batched so each measurement lasts about that long.
    """
    wanted = {name: repeats if isinstance(repeats, int) else repeats[name] for name in functions}
    times: dict[str, list[float]] = {name: [] for name in functions}
    number: dict[str, int] = {}
    gc.collect()
    for name, fn in functions.items():
        first = _measure(fn, 1)
        if first >= MIN_REPEAT_TIME:
            number[name] = 1
            times[name].append(first)
        else:
            number[name] = max(1, int(np.ceil(MIN_REPEAT_TIME / max(first, 1e-7))))
    for _ in range(max(wanted.values())):
        for name, fn in functions.items():
            if len(times[name]) < wanted[name]:
                times[name].append(_measure(fn, number[name]))
    return {name: Timing(min(values), len(values), number[name]) for name, values in times.items()}


def fmt_time(seconds: float) -> str:
    """A time with a unit that keeps three significant digits."""
    if seconds < 1e-3:
        return f"{seconds * 1e6:.3g} µs"
    if seconds < 1.0:
        return f"{seconds * 1e3:.3g} ms"
    return f"{seconds:.3g} s"


def fmt_ratio(value: float) -> str:
    """A ratio such as ``71.9x``."""
    return f"{value:.3g}x" if value < 100 else f"{value:.0f}x"


def fmt_bytes(value: float) -> str:
    """Bytes with a binary unit."""
    for unit in ("B", "KiB", "MiB", "GiB"):
        if abs(value) < 1024 or unit == "GiB":
            return f"{value:.3g} {unit}" if unit != "B" else f"{value:.0f} B"
        value /= 1024
    return f"{value:.3g} GiB"  # pragma: no cover


def md_table(headers: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A GitHub markdown table."""
    lines = [
        "| " + " | ".join(headers) + " |",
        "|" + "|".join("---" for _ in headers) + "|",
    ]
    lines += ["| " + " | ".join(str(cell) for cell in row) + " |" for row in rows]
    return "\n".join(lines)


def write_section(name: str, text: str) -> Path:
    """Write ``bench/output/<name>.md`` and return its path."""
    OUTPUT_DIR.mkdir(parents=True, exist_ok=True)
    path = OUTPUT_DIR / f"{name}.md"
    path.write_text(text.rstrip() + "\n", encoding="utf-8")
    print(f"wrote {path.relative_to(ROOT)}", file=sys.stderr)
    return path


class _Tee(io.StringIO):
    """Keeps what is written and passes it on to ``out``."""

    def __init__(self, out: Any) -> None:
        super().__init__()
        self._out = out

    def write(self, text: str) -> int:
        self._out.write(text)
        return super().write(text)

    def flush(self) -> None:
        self._out.flush()


@contextlib.contextmanager
def printed_section(name: str, heading: str, intro: str = "") -> Iterator[None]:
    """For a script that prints its tables as it goes: print as usual, and when the block
    ends write what it printed as the section ``bench/output/<name>.md`` (``heading``, the
    command line, the machine and its load, ``intro``, then the printed text), so that
    ``run_all.py`` puts it into ``BENCHMARKS.md`` like every other section."""
    started = time.perf_counter()
    machine = machine_description()
    tee = _Tee(sys.stdout)
    with contextlib.redirect_stdout(tee):
        yield
    head = f"{heading}\n\n`{command_line()}`. Machine: {machine}."
    head += f" Run time {time.perf_counter() - started:.0f} s."
    if intro:
        head += "\n\n" + intro.strip()
    write_section(name, head + "\n\n" + tee.getvalue().strip())


INVALID_RESIDUAL = 1e3  # residual value returned at invalid parameter points


def simulation_residual(structure: Any, u: Any, y: Any, x0: float) -> Any:
    """Free-run simulation error with the vectorised simulation; ``INVALID_RESIDUAL`` everywhere
    at invalid points (what a user would hand to ``scipy.optimize.least_squares``)."""
    from genbacklash_core.refine import simulate_parameters

    invalid = np.full(y.size, INVALID_RESIDUAL)

    def residual(p: Any) -> Any:
        if structure.problem(p) is not None:
            return invalid
        return simulate_parameters(structure, p, u, x0)[1] - y

    return residual


def physics_parser(description: str | None, duration: float) -> argparse.ArgumentParser:
    """A physics bench's parser with its grid: ``--seeds`` (0 1 2), ``--bandwidths`` (20 60
    100 Hz), ``--variants`` (all of :data:`~genbacklash_ros.physics.variants.VARIANTS`) and
    ``--duration`` (s; default ``duration``)."""
    from genbacklash_ros.physics.variants import VARIANTS

    parser = argparse.ArgumentParser(description=(description or "").split("\n\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument(
        "--bandwidths", type=positive, nargs="+", default=[20.0, 60.0, 100.0], metavar="HZ"
    )
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS))
    parser.add_argument("--duration", type=positive, default=duration, metavar="S")
    return parser


def positive(text: str) -> float:
    """An argument that must be a finite number above 0 (``argparse`` type): a servo's
    bandwidth, a record's duration.

    >>> positive("2.5")
    2.5
    >>> positive("0")
    Traceback (most recent call last):
    ...
    argparse.ArgumentTypeError: must be a number > 0, got '0'
    """
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f"must be a number > 0, got {text!r}")
    return value


@dataclass(frozen=True)
class PhysicsRecord:
    """One record of a physics bench's grid (:func:`physics_records`): its variant, servo
    bandwidth (Hz) and seed, the drivetrain's parameters and its quasi-static truth
    (:func:`~genbacklash_ros.physics.truth.quasi_static` over the operation scenario's
    travel)."""

    name: str
    bandwidth: float
    seed: int
    params: Any
    truth: Any


def physics_records(args: argparse.Namespace) -> Iterator[PhysicsRecord]:
    """The records of :func:`physics_parser`'s grid, variant by variant, bandwidth by
    bandwidth, seed by seed; each drivetrain and its truth built once for its seeds."""
    from genbacklash_core.scenarios import OperationSettings
    from genbacklash_ros.physics.truth import quasi_static
    from genbacklash_ros.physics.variants import variant

    for name in args.variants:
        for bw in args.bandwidths:
            params = variant(name, bandwidth=bw)
            truth = quasi_static(params, OperationSettings().travel)
            for seed in args.seeds:
                yield PhysicsRecord(name, bw, seed, params, truth)


def rms(e: np.ndarray) -> float:
    """The root-mean-square of ``e``."""
    return float(np.sqrt(np.mean(e * e)))


def parse_physics_arguments(
    parser: argparse.ArgumentParser, argv: Sequence[str] | None
) -> argparse.Namespace:
    """Add ``--quick`` to a physics bench's ``parser`` and parse ``argv``; ``--quick``: seed
    0, near_ideal at 60 Hz, 10 s records (a smoke test)."""
    parser.add_argument("--quick", action="store_true", help="smaller settings (smoke test)")
    args = parser.parse_args(argv)
    if args.quick:
        args.seeds, args.bandwidths = [0], [60.0]
        args.variants, args.duration = ["near_ideal"], 10.0
    return args


PHYSICS_TOPICS = ["--command", "/command", "--encoder", "/encoder", "--joint", "drive_joint"]
"""The topics and joint of a physics bag (``genbacklash simulate --physics``)."""


def cli_json(args: list[str]) -> dict[str, object]:
    """Run ``genbacklash ARGS`` (with ``--json``) in process, its output silenced; its JSON."""
    from genbacklash_ros.cli.main import main as genbacklash

    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        genbacklash(args)
    return dict(json.loads(out.getvalue()))


def json_play(result: dict[str, object]) -> float:
    """c_L + c_R of identify's JSON or of replay's (its ``model`` holds the same shape)."""
    shape = result.get("model") if "backlash" not in result else result
    assert isinstance(shape, dict)
    bl = shape["backlash"]
    assert isinstance(bl, dict)
    return float(bl["c_left"]) + float(bl["c_right"])


def param_values(pairs: Sequence[str]) -> dict[str, object]:
    """``--param NAME=VALUE`` pairs as node parameters: a value is a number where it reads
    as one, else the text.

    >>> param_values(["servo_model=auto", "servo_window=4"])
    {'servo_model': 'auto', 'servo_window': 4.0}
    """
    values: dict[str, object] = {}
    for name, _, text in (p.partition("=") for p in pairs):
        try:
            values[name] = float(text)
        except ValueError:
            values[name] = text
    return values
