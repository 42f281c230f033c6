"""Speed and memory of the identification against generic fits and per-sample loops.

Writes ``bench/output/speed.md`` and ``bench/output/speed.png``; the memory measurements run
``bench/_memory_child.py`` in fresh processes.

    python bench/speed.py [--quick]
"""

from __future__ import annotations

import json
import subprocess
import sys
import tempfile
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from _common import (
    BENCH_DIR,
    INVALID_RESIDUAL,
    OUTPUT_DIR,
    ROOT,
    command_line,
    fmt_bytes,
    fmt_ratio,
    fmt_time,
    machine_description,
    md_table,
    parse_args,
    simulation_residual,
    time_interleaved,
    write_section,
)
from scipy.optimize import least_squares
from tqdm import tqdm

from genbacklash_core import (
    GeneralBacklash,
    identify_backlash,
    identify_cascade,
    paper_example,
    simulate_backlash_loop,
    simulate_cascade_loop,
)
from genbacklash_core.structure import Structure
from genbacklash_ros.bags.csvio import Series, read_series_csv, write_series_csv

TARGET_GENERIC = 50.0  # identify must be at least 50x faster than the generic loop fit
TARGET_PASSES = 1.5  # identify_cascade incl. CSV read: < 1.5 per-sample passes at N = 1e6
TARGET_BYTES = 1024.0  # peak memory per sample of identify_cascade
GENERIC_MAX_N = 10**5  # the generic least-squares fit is skipped above this N


def backlash_residual_loop(
    u: np.ndarray, y: np.ndarray, structure: Structure
) -> Callable[[np.ndarray], np.ndarray]:
    """What a user would write: build the model from p, simulate it sample by sample."""
    invalid = np.full(y.size, INVALID_RESIDUAL)
    x0 = float(y[0])

    def residual(p: np.ndarray) -> np.ndarray:
        if structure.problem(p) is not None:
            return invalid
        model = GeneralBacklash.from_parameters(p, structure.degree)
        return simulate_backlash_loop(model, u, x0) - y

    return residual


def counted(fn: Callable[[np.ndarray], np.ndarray]) -> tuple[Callable[..., np.ndarray], list[int]]:
    """Wrap a residual to count its calls."""
    calls = [0]

    def wrapper(p: np.ndarray) -> np.ndarray:
        calls[0] += 1
        return fn(p)

    return wrapper, calls


def rmse(p: np.ndarray, truth: np.ndarray) -> float:
    return float(np.sqrt(np.mean((np.asarray(p) - truth) ** 2)))


# ---- (i) Example 1: identify vs generic fits ---------------------------------------------------


def part_generic(quick: bool) -> tuple[list[list[str]], dict[str, float]]:
    example = paper_example(1)
    truth = example.model.parameters()
    structure = Structure(3, 0, 0, 1.0)
    seeds = range(2) if quick else range(5)
    rows: list[list[str]] = []
    loop_ratios: list[float] = []
    vec_ratios: list[float] = []
    for seed in tqdm(seeds, desc="speed (i): Example 1 seeds", file=sys.stderr):
        data = example.generate(seed)  # N = 800, SNR 25 (the paper's setting)
        u, y = data.u, data.y
        res_loop = backlash_residual_loop(u, y, structure)
        res_vec = simulation_residual(structure, u, y, float(y[0]))
        start = structure.start()
        # One untimed run each for the call counts and the estimates.
        ident = identify_backlash(u, y, 3)
        wrapped, loop_calls = counted(res_loop)
        fit_loop = least_squares(wrapped, start)
        wrapped, vec_calls = counted(res_vec)
        fit_vec = least_squares(wrapped, start)
        t = time_interleaved(
            {
                "identify": lambda u=u, y=y: identify_backlash(u, y, 3),
                "loop": lambda r=res_loop, s=start: least_squares(r, s),
                "vec": lambda r=res_vec, s=start: least_squares(r, s),
            },
            # best of 9: a machine hiccup during one round must not set a seed's time
            repeats={"identify": 9, "loop": 1 if quick else 3, "vec": 9},
        )
        loop_ratio = t["loop"].best / t["identify"].best
        vec_ratio = t["vec"].best / t["identify"].best
        loop_ratios.append(loop_ratio)
        vec_ratios.append(vec_ratio)
        rows.append(
            [
                str(seed),
                f"{fmt_time(t['identify'].best)} ({t['identify'].label})",
                f"{fmt_time(t['loop'].best)} ({t['loop'].label}; {loop_calls[0]} sims)",
                f"{fmt_time(t['vec'].best)} ({t['vec'].label}; {vec_calls[0]} sims)",
                fmt_ratio(loop_ratio),
                fmt_ratio(vec_ratio),
                f"{rmse(ident.model.parameters(), truth):.4f} / {rmse(fit_loop.x, truth):.4f}"
                f" / {rmse(fit_vec.x, truth):.4f}",
            ]
        )
    stats = {
        "loop_min": min(loop_ratios),
        "loop_median": float(np.median(loop_ratios)),
        "vec_min": min(vec_ratios),
        "vec_median": float(np.median(vec_ratios)),
    }
    return rows, stats


# ---- (ii) cascade: identify incl. CSV vs one per-sample pass ---------------------------------


def part_cascade(quick: bool, workdir: Path) -> tuple[list[dict[str, object]], dict[str, float]]:
    example = paper_example(3)
    truth = example.model.parameters()
    structure = Structure(3, 2, 2, 1.0)
    sizes = [10**3, 10**4, 10**5] if quick else [10**3, 10**4, 10**5, 10**6]
    out: list[dict[str, object]] = []
    for n in tqdm(sizes, desc="speed (ii): cascade N", file=sys.stderr):
        data = example.generate(seed=0, n_samples=n)
        path = workdir / f"cascade_{n}.csv"
        write_series_csv(path, Series(data.u, data.y))
        series = read_series_csv(path)
        u, y = series.u, series.y
        result = identify_cascade(u, y, 3, 2, 2)

        def read_and_identify(path: Path = path) -> object:
            s = read_series_csv(path)
            return identify_cascade(s.u, s.y, 3, 2, 2)

        functions: dict[str, Callable[[], object]] = {
            "identify": read_and_identify,
            "read": lambda path=path: read_series_csv(path),
            "loop": lambda u=u: simulate_cascade_loop(example.model, u),
        }
        repeats = {
            "identify": 3 if n >= 10**6 else 5,
            "read": 3 if n >= 10**6 else 5,
            "loop": 2 if n >= 10**6 else 3,
        }
        generic_error = None
        generic_calls = None
        if n <= GENERIC_MAX_N:
            residual = simulation_residual(structure, u, y, 0.0)
            wrapped, calls = counted(residual)
            fit = least_squares(wrapped, structure.start())
            generic_error = float(np.max(np.abs(fit.x - truth)))
            generic_calls = calls[0]
            functions["generic"] = lambda r=residual: least_squares(r, structure.start())
            repeats["generic"] = 1 if n >= 10**5 else 3
        t = time_interleaved(functions, repeats)
        out.append(
            {
                "n": n,
                "t": t,
                "converged": result.converged,
                "error": float(np.max(np.abs(result.model.parameters() - truth))),
                "generic_error": generic_error,
                "generic_calls": generic_calls,
                "csv_bytes": path.stat().st_size,
            }
        )
        path.unlink()
    last = out[-1]
    t_last = last["t"]
    assert isinstance(t_last, dict)
    stats = {"n": float(last["n"]), "passes": t_last["identify"].best / t_last["loop"].best}
    return out, stats


# ---- (iii) memory in a fresh process -----------------------------------------------------------


def part_memory(quick: bool, workdir: Path) -> list[dict[str, float]]:
    example = paper_example(3)
    sizes = [10**4, 10**5] if quick else [10**5, 10**6]
    rows = []
    for n in tqdm(sizes, desc="speed (iii): memory N", file=sys.stderr):
        data = example.generate(seed=0, n_samples=n)
        directory = workdir / f"mem_{n}"
        directory.mkdir()
        np.save(directory / "u.npy", data.u)
        np.save(directory / "y.npy", data.y)
        row: dict[str, float] = {"n": n}
        for mode in ("rss", "tracemalloc"):
            completed = subprocess.run(
                [sys.executable, str(BENCH_DIR / "_memory_child.py"), str(directory), mode],
                check=True,
                capture_output=True,
                text=True,
                cwd=ROOT,
            )
            info = json.loads(completed.stdout.strip().splitlines()[-1])
            row[mode] = float(info["extra"])
            if not info["converged"]:
                print(f"warning: identify_cascade did not converge at N={n}", file=sys.stderr)
            if mode == "rss":
                row["base"] = float(info["base"])
                row["base_peak"] = float(info["base_peak"])
                row["import_peak"] = float(info["import_peak"])
                row["reset"] = float(info["reset"])
                row["ru_before"] = float(info["ru_maxrss_before"])
                row["ru_after"] = float(info["ru_maxrss_after"])
        rows.append(row)
    return rows


# ---- report ----------------------------------------------------------------------------------


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], sys.argv[1:])
    warnings.simplefilter("ignore", RuntimeWarning)
    machine = machine_description()
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="genbacklash-bench-") as tmp:
        workdir = Path(tmp)
        generic_rows, generic_stats = part_generic(args.quick)
        cascade_rows, cascade_stats = part_cascade(args.quick, workdir)
        memory_rows = part_memory(args.quick, workdir)
    cmd = command_line()

    # ---- plot -------------------------------------------------------------------------------
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ns = [r["n"] for r in cascade_rows]
    timings = [r["t"] for r in cascade_rows]
    ax.loglog(ns, [t["identify"].best for t in timings], "o-", label="read CSV + identify_cascade")
    ax.loglog(ns, [t["read"].best for t in timings], "^:", label="read CSV only")
    ax.loglog(ns, [t["loop"].best for t in timings], "s--", label="one per-sample loop pass")
    gen = [(r["n"], r["t"]["generic"].best) for r in cascade_rows if "generic" in r["t"]]
    if gen:
        ax.loglog(*zip(*gen, strict=True), "v-.", label="generic least_squares (vectorised)")
    ax.set_xlabel("samples N")
    ax.set_ylabel("time [s]")
    ax.set_title("Cascade identification (Example 3 model)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    OUTPUT_DIR.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUTPUT_DIR / "speed.png", dpi=120)
    plt.close(fig)

    # ---- markdown ---------------------------------------------------------------------------
    def verdict(ok: bool) -> str:
        return "met" if ok else "**not met**"

    table_i = md_table(
        [
            "seed",
            "identify_backlash (default)",
            "generic fit, loop simulation",
            "generic fit, vectorised simulation",
            "loop fit / identify",
            "vectorised fit / identify",
            "RMSE identify / loop fit / vec. fit",
        ],
        generic_rows,
    )
    rows_ii = []
    for r in cascade_rows:
        t = r["t"]
        generic = (
            f"{fmt_time(t['generic'].best)} ({t['generic'].label}; {r['generic_calls']} sims; "
            f"max err {r['generic_error']:.3g})"
            if "generic" in t
            else f"skipped (N > {GENERIC_MAX_N:,})"
        )
        rows_ii.append(
            [
                f"{r['n']:,}",
                f"{fmt_time(t['identify'].best)} ({t['identify'].label})",
                f"{fmt_time(t['read'].best)}",
                f"{fmt_time(t['loop'].best)} ({t['loop'].label})",
                f"{t['identify'].best / t['loop'].best:.2f}",
                generic,
                f"{'yes' if r['converged'] else 'no'}, {r['error']:.3g}",
            ]
        )
    table_ii = md_table(
        [
            "N",
            "read CSV + identify_cascade",
            "of which read CSV",
            "one per-sample pass (simulate_cascade_loop)",
            "passes (identify / loop)",
            "generic least_squares fit",
            "identify converged, max abs error",
        ],
        rows_ii,
    )
    rows_iii = [
        [
            f"{int(r['n']):,}",
            f"{fmt_bytes(r['rss'])} ({r['rss'] / r['n']:.0f} B/sample)",
            f"{fmt_bytes(r['tracemalloc'])} ({r['tracemalloc'] / r['n']:.0f} B/sample)",
            f"{fmt_bytes(r['import_peak'])} -> {fmt_bytes(r['base_peak'])}"
            + ("" if r["reset"] else " (reset failed)"),
        ]
        for r in memory_rows
    ]
    table_iii = md_table(
        [
            "N",
            "peak RSS - RSS before identify",
            "tracemalloc peak during identify",
            "peak RSS after imports + data -> after reset",
        ],
        rows_iii,
    )
    ru_note = (
        "here `ru_maxrss` was already "
        + " / ".join(fmt_bytes(r["ru_before"]) for r in memory_rows)
        + " before the identification at N = "
        + " / ".join(f"{int(r['n']):,}" for r in memory_rows)
    )
    mem_worst_rss = max(r["rss"] / r["n"] for r in memory_rows)
    mem_worst_tm = max(r["tracemalloc"] / r["n"] for r in memory_rows)
    n_last = f"{int(cascade_stats['n']):,}"
    text = f"""## Speed and memory

What is measured, on {machine}:
(i) the paper's Example 1 (N = 800, SNR 25, seeds 0..{len(generic_rows) - 1}): the default
`identify_backlash(u, y, 3)` (iteration + output-error refinement) against the generic fit a user
would otherwise write, `scipy.optimize.least_squares` (default method, finite-difference
Jacobian) on the free-run simulation error from the paper's start, once with the simulation as a
per-sample Python loop (`simulate_backlash_loop` on a model built from the parameters) and once
with the vectorised `simulate_parameters`; invalid points return {INVALID_RESIDUAL:g} at every
sample. (ii) Cascade identification on data of the Example 3 model
(`paper_example(3).generate(seed=0, n_samples=N)`, written to CSV first): `read_series_csv` +
`identify_cascade(u, y, 3, 2, 2)` against one per-sample Python pass over the same data
(`simulate_cascade_loop` with the true model), and the generic least-squares fit with the
vectorised simulation (skipped above N = {GENERIC_MAX_N:,}). (iii) Peak memory of
`identify_cascade` in a fresh subprocess per measurement, on data loaded from `.npy` files. Times
are best of k, functions in one row timed round-robin in the same run; the ratios are the
numbers to compare across machines.

### (i) Example 1: identify vs a generic output-error fit

{table_i}

Command: `{cmd}`

"sims" is the number of residual evaluations (simulations) the generic fit needed, Jacobian
columns included. Target: identify at least {TARGET_GENERIC:.0f}x faster than the generic fit
with a per-sample loop simulation — {verdict(generic_stats["loop_min"] >= TARGET_GENERIC)}
(smallest ratio over the seeds {fmt_ratio(generic_stats["loop_min"])}, median
{fmt_ratio(generic_stats["loop_median"])}). Against the generic fit with the vectorised
simulation, identify is {fmt_ratio(generic_stats["vec_median"])} faster (median; smallest
{fmt_ratio(generic_stats["vec_min"])}); all three reach practically the same estimate here.

### (ii) Cascade identification including reading the CSV

{table_ii}

Command: `{cmd}`

![cascade timings](bench/output/speed.png)

Target: read CSV + identify_cascade in less than {TARGET_PASSES} per-sample Python passes at
N = {n_last} — {verdict(cascade_stats["passes"] < TARGET_PASSES)}
({cascade_stats["passes"]:.2f} passes). "max err" / "max abs error" is the largest absolute
parameter error against the true model.

### (iii) Peak memory of identify_cascade

{table_iii}

Command: `{cmd}`

Two measurements, each in its own fresh process after imports and after loading the data. RSS:
the peak resident set size after the identification minus the resident set size
(`/proc/self/statm`) just before it, with the peak first reset to the current RSS by writing `5`
to `/proc/self/clear_refs` so that the import peak cannot mask the measurement (last column).
The peak is read as `VmHWM` from `/proc/self/status`, the same counter as
`getrusage(RUSAGE_SELF).ru_maxrss` except that `ru_maxrss` also keeps the peak of the address
space replaced at `exec` — after the `vfork` that `subprocess` uses, the benchmark parent's peak
({ru_note}) — so it cannot be reset and would mask the child's own peak;
and `tracemalloc`'s peak of traced allocations during the identification (numpy reports its
array buffers to tracemalloc; the input arrays, allocated before tracing starts, are not
counted). The child process (`bench/_memory_child.py`) imports only numpy and genbacklash_core.
RSS counts every page touched, including allocator slack and freed-but-not-returned memory;
tracemalloc counts only live Python/numpy allocations. Target: at most {TARGET_BYTES:.0f} B per
sample — {verdict(max(mem_worst_rss, mem_worst_tm) <= TARGET_BYTES)} (worst:
{mem_worst_rss:.0f} B/sample by RSS, {mem_worst_tm:.0f} B/sample by tracemalloc).

Section run time: {time.perf_counter() - started:.0f} s.
"""
    write_section("speed", text)


if __name__ == "__main__":
    main()
