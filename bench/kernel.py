"""Benchmark the play-operator kernel and the backlash simulation against per-sample loops.

Writes ``bench/output/kernel.md`` and ``bench/output/kernel.png``.

    python bench/kernel.py [--quick]
"""

from __future__ import annotations

import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from _common import (
    OUTPUT_DIR,
    command_line,
    fmt_ratio,
    fmt_time,
    machine_description,
    md_table,
    parse_args,
    time_interleaved,
    write_section,
)
from tqdm import tqdm

from genbacklash_core import (
    paper_example,
    play,
    play_operator,
    play_operator_loop,
    simulate_backlash,
    simulate_backlash_loop,
)
from genbacklash_core.simulate import play_bounds

SEED = 20240601
TARGET_RATIO = 20.0  # the kernel must take at most 1/20 of a per-sample loop at N = 1e6
X0 = 0.0  # state before the first sample
REPEATS = 5  # best of 5 for the fast calls (at least the 3 asked for)


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], sys.argv[1:])
    sizes = [10**3, 10**4, 10**5] if args.quick else [10**3, 10**4, 10**5, 10**6]
    machine = machine_description()
    model = paper_example(1).model
    kernel_rows: list[dict[str, float | int | str | bool]] = []
    sim_rows: list[dict[str, float | int | str | bool]] = []
    for n in tqdm(sizes, desc="kernel: N", file=sys.stderr):
        rng = np.random.default_rng(SEED + n)
        u = rng.uniform(-2.0, 2.0, n)  # the paper's input: uniform in (-u_max, u_max)
        lo, hi = play_bounds(model.left(u), model.right(u))

        # Play operator: scan vs the tight float loop.
        fast = play_operator(lo, hi, X0)
        slow = play_operator_loop(lo, hi, X0)
        t = time_interleaved(
            {
                "scan": lambda lo=lo, hi=hi: play_operator(lo, hi, X0),
                "loop": lambda lo=lo, hi=hi: play_operator_loop(lo, hi, X0),
            },
            repeats=REPEATS,
        )
        kernel_rows.append(
            {
                "n": n,
                "scan": t["scan"].best,
                "scan_runs": t["scan"].label,
                "loop": t["loop"].best,
                "loop_runs": t["loop"].label,
                "diff": float(np.max(np.abs(fast - slow))),
                "identical": bool(np.array_equal(fast, slow)),
            }
        )

        # Simulation: vectorised (branches + scan) vs the per-sample loop of eq. (20).
        fast = simulate_backlash(model, u, X0)
        slow_runs = 1 if n >= 10**6 else REPEATS
        timed: dict[str, object] = {}

        def run_loop(u: np.ndarray = u, timed: dict[str, object] = timed) -> None:
            timed["out"] = simulate_backlash_loop(model, u, X0)

        t = time_interleaved(
            {"vec": lambda u=u: simulate_backlash(model, u, X0), "loop": run_loop},
            repeats={"vec": REPEATS, "loop": slow_runs},
        )
        slow = timed["out"]
        assert isinstance(slow, np.ndarray)
        sim_rows.append(
            {
                "n": n,
                "vec": t["vec"].best,
                "vec_runs": t["vec"].label,
                "loop": t["loop"].best,
                "loop_runs": t["loop"].label,
                "diff": float(np.max(np.abs(fast - slow))),
                "identical": bool(np.array_equal(fast, slow)),
            }
        )

    # Decomposition of simulate_backlash at the largest N: branch polynomials vs the scan.
    n_big = sizes[-1]
    u_big = np.random.default_rng(SEED + n_big).uniform(-2.0, 2.0, n_big)
    lo_big, hi_big = play_bounds(model.left(u_big), model.right(u_big))
    parts = time_interleaved(
        {
            "branches": lambda: play_bounds(model.left(u_big), model.right(u_big)),
            "scan": lambda: play_operator(lo_big, hi_big, 0.0),
            "one_pass": lambda: np.maximum(lo_big, hi_big),
        },
        repeats=REPEATS,
    )

    # ---- plot -------------------------------------------------------------------------------
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ns = [r["n"] for r in kernel_rows]
    ax.loglog(ns, [r["scan"] for r in kernel_rows], "o-", label="play_operator (numpy scan)")
    ax.loglog(ns, [r["loop"] for r in kernel_rows], "s--", label="play_operator_loop")
    ax.loglog(ns, [r["vec"] for r in sim_rows], "o-", label="simulate_backlash")
    ax.loglog(ns, [r["loop"] for r in sim_rows], "s--", label="simulate_backlash_loop (eq. 20)")
    ax.set_xlabel("samples N")
    ax.set_ylabel("time [s]")
    ax.set_title("Backlash kernel: vectorised vs per-sample loop")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    OUTPUT_DIR.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUTPUT_DIR / "kernel.png", dpi=120)
    plt.close(fig)

    # ---- markdown ---------------------------------------------------------------------------
    cmd = command_line()
    ktable = md_table(
        [
            "N",
            "play_operator (scan)",
            "play_operator_loop",
            "loop / scan",
            "max abs diff",
            "bit-identical",
        ],
        [
            [
                f"{r['n']:,}",
                f"{fmt_time(r['scan'])} ({r['scan_runs']})",
                f"{fmt_time(r['loop'])} ({r['loop_runs']})",
                fmt_ratio(r["loop"] / r["scan"]),
                f"{r['diff']:.1e}",
                "yes" if r["identical"] else "no",
            ]
            for r in kernel_rows
        ],
    )
    stable = md_table(
        [
            "N",
            "simulate_backlash",
            "simulate_backlash_loop",
            "loop / vectorised",
            "max abs diff",
            "bit-identical",
        ],
        [
            [
                f"{r['n']:,}",
                f"{fmt_time(r['vec'])} ({r['vec_runs']})",
                f"{fmt_time(r['loop'])} ({r['loop_runs']})",
                fmt_ratio(r["loop"] / r["vec"]),
                f"{r['diff']:.1e}",
                "yes" if r["identical"] else "no",
            ]
            for r in sim_rows
        ],
    )
    k_last, s_last = kernel_rows[-1], sim_rows[-1]
    k_ratio = k_last["loop"] / k_last["scan"]
    s_ratio = s_last["loop"] / s_last["vec"]
    n_label = f"{n_big:,}"

    def verdict(ratio: float) -> str:
        return "met" if ratio >= TARGET_RATIO else "**not met**"

    small_n = ""
    slower = [r for r in kernel_rows if r["loop"] < r["scan"]]
    if slower:
        sizes_slower = ", ".join(f"{r['n']:,}" for r in slower)
        small_n = (
            f"At N = {sizes_slower} the scan is slower than the float"
            f" loop; `play_operator` switches to the loop only below {play._LOOP_BELOW} samples"
            " (`genbacklash_core.play._LOOP_BELOW`).\n\n"
        )
    conservative = ""
    if s_last["loop_runs"] == "1 run" and len(sim_rows) > 1:
        # A single run of the slow loop is exposed to load; scale the best-of-k time at the
        # next smaller N linearly for a more conservative figure.
        prev = sim_rows[-2]
        scaled = prev["loop"] * (s_last["n"] / prev["n"]) / s_last["vec"]
        conservative = (
            f" The {n_label}-sample loop is a single run; scaling the best-of-{REPEATS} loop time"
            f" at N = {prev['n']:,} linearly to {n_label} gives a more conservative"
            f" {fmt_ratio(scaled)} (target {verdict(scaled)})."
        )

    text = f"""## Kernel: the play operator and the backlash simulation

What is measured: the state recursion of the backlash,
`x(t) = min(max(x(t-1), lo(t)), hi(t))` (the play operator, eqs. 8/13/20 with branch values
`lo = min(L, R)`, `hi = max(L, R)`), as computed by `genbacklash_core.play.play_operator` (a
two-level clamp-composition scan in numpy) and by `play_operator_loop` (a tight per-sample Python
loop over floats, lists in and out); and the whole simulation `simulate_backlash` (Horner branch
evaluation + scan) against `simulate_backlash_loop` (the per-sample loop of the paper's eq. 20
that evaluates both branch polynomials and the switching functions at every sample). Model: the
paper's Example 1; input uniform in (-2, 2), seeded. Times are per call, best of k (calls under
20 ms are batched as in `timeit`), and the functions compared in one row are timed round-robin
in the same run, so the ratios are less sensitive to load than the absolute times. Machine:
{machine}.

{ktable}

Command: `{cmd}`

{stable}

Command: `{cmd}`

![kernel timings](bench/output/kernel.png)

Target: the kernel runs {n_label} samples in at most 1/{TARGET_RATIO:.0f} of the time of a
straightforward per-sample Python loop.

* Against the tight float loop `play_operator_loop` (only the clamp, no branch evaluation): the
  scan is {fmt_ratio(k_ratio)} faster at N = {n_label} — target {verdict(k_ratio)}.
* Against the straightforward per-sample loop of eq. (20) `simulate_backlash_loop` (what the
  paper's equations give when typed in directly): `simulate_backlash` is {fmt_ratio(s_ratio)}
  faster at N = {n_label} — target {verdict(s_ratio)}.{conservative}

{small_n}The play-operator results are bit-identical to the loop (the scan only selects with
min/max). The simulation differs from the eq.-(20) loop by at most {s_last["diff"]:.1e}: rounding
in the branch polynomials, which the loop sums term by term (`m_i * xi**i`) and the vectorised
path evaluates by Horner's rule; the state recursion itself adds no error.

At N = {n_label}, `simulate_backlash` splits into branch evaluation
({fmt_time(parts["branches"].best)}: two cubic polynomials and `play_bounds`) and the scan
({fmt_time(parts["scan"].best)}); one elementwise numpy pass over the same data
(`np.maximum(lo, hi)`) takes {fmt_time(parts["one_pass"].best)}, so the scan costs about
{parts["scan"].best / parts["one_pass"].best:.0f} such passes.

### Why a numpy scan and not a compiled path

The recursion is sequential, but every step is a clamp and a composition of clamps is again a
clamp, so the series can be cut into blocks of about sqrt(N)/4 samples, each block composed into
one clamp with vectorised min/max over the blocks, the block clamps chained in Python, and all
blocks then run at once from their start states. Every operation is a min or a max that selects
one of its inputs, so the result is exactly the per-sample loop's (the table shows bit-identical
output at every N) — no tolerance argument is needed, unlike a float associative scan of a linear
recursion. It needs no compiler and no extra dependency: numba or Cython would add a build or
JIT step and a heavyweight install to a package whose core is numpy + scipy only. Measured here:
{fmt_time(k_last["scan"])} for {n_label} samples ({k_last["scan"] / n_big * 1e9:.0f} ns per
sample), {fmt_ratio(k_ratio)} faster than the tightest pure-Python loop and
{fmt_ratio(s_ratio)} faster (whole simulation) than the loop of eq. (20). This is not the
fastest possible: a compiled loop would run at roughly memory speed — one elementwise numpy pass
over the data takes {fmt_time(parts["one_pass"].best)} here, so a compiled kernel could be up to
about {parts["scan"].best / parts["one_pass"].best:.0f}x faster than the scan (an estimate: no
compiled variant is measured, as none is installed), saving at most
{fmt_time(parts["scan"].best - parts["one_pass"].best)} per {n_label}-sample simulation. The
identification runs a handful of simulations per iteration, and each costs far less than reading
the same samples from CSV (see the speed section), so that saving would not change the picture.
"""
    write_section("kernel", text)


if __name__ == "__main__":
    main()
