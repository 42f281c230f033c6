"""Discrepancy diagnosis: is the right effect named, nothing on clean data, how far the gap shrinks.

    python bench/diagnose.py [--quick]

Generated records (``genbacklash_core.diagnose.synthetic_case``): an ideal backlash (random slope
0.7-1.3, gaps 0.15-0.4) driven by a filtered random walk (AR(1) velocity, reflected at +/-2;
every fourth single-effect and clean record uses the paper's i.i.d. uniform input instead),
white output noise at SNR 20-50,
with each catalog effect hidden at a random strength: cubic branches, a first- or second-order
lag (poles 0.5-0.85, unit static gain), a dead time of 2-8 samples, an output offset larger
than the dead zones, a gap growing 50-150% over the record, an output limit cutting 5-15% of
the output range. ``diagnose`` runs with its defaults (70% estimation, 30% validation).
"""

from __future__ import annotations

import itertools
import sys
import time
from dataclasses import dataclass

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from _common import (
    OUTPUT_DIR,
    command_line,
    machine_description,
    md_table,
    parse_args,
    write_section,
)
from tqdm import tqdm

from genbacklash_core.diagnose import (
    EFFECT_NAMES,
    diagnose,
    measure_gap,
    split_record,
    synthetic_case,
)

SEED = 51_000


@dataclass(frozen=True)
class Outcome:
    kind: str  # "single", "clean", "pair"
    hidden: tuple[str, ...]
    named: tuple[str, ...]
    gap_initial: float
    gap_first: float  # after the first step (= initial when nothing was named)
    gap_final: float
    gap_truth: float  # the true model's validation gap: the noise floor
    seconds: float
    description: str
    input_kind: str

    @property
    def first_right(self) -> bool:
        return bool(self.named) and self.named[0] == self.hidden[0]

    @property
    def shrink(self) -> float:
        return 1.0 - self.gap_first / self.gap_initial

    @property
    def excess_closed(self) -> float:
        """Share of the gap above the noise floor that the first step removed."""
        excess = self.gap_initial - self.gap_truth
        return (self.gap_initial - self.gap_first) / excess if excess > 0 else float("nan")


def run_case(kind: str, effects: tuple[str, ...], seed: int, n: int, input_kind: str) -> Outcome:
    case = synthetic_case(list(effects), seed, n, input_kind=input_kind)
    started = time.perf_counter()
    result = diagnose(case.u, case.y)
    seconds = time.perf_counter() - started
    truth = measure_gap(case.truth, case.u, case.y, split_record(n, 0.3)).gap
    first = result.steps[0].gap_after if result.steps else result.gap_initial
    return Outcome(
        kind,
        effects,
        result.effects,
        result.gap_initial,
        first,
        result.gap_final,
        truth,
        seconds,
        case.description,
        input_kind,
    )


def cases(quick: bool) -> list[tuple[str, tuple[str, ...], int, str]]:
    singles = 2 if quick else 8
    cleans = 4 if quick else 20
    out: list[tuple[str, tuple[str, ...], int, str]] = []
    seed = SEED
    for effect in EFFECT_NAMES:
        for i in range(singles):
            out.append(("single", (effect,), seed, "uniform" if i % 4 == 3 else "walk"))
            seed += 1
    for i in range(cleans):
        out.append(("clean", (), seed, "uniform" if i % 4 == 3 else "walk"))
        seed += 1
    pairs = list(itertools.combinations(EFFECT_NAMES, 2))
    for pair in pairs[:: 3 if quick else 1]:
        out.append(("pair", pair, seed, "walk"))
        seed += 1
    return out


def plot(outcomes: list[Outcome]) -> None:
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.4))
    colours = {name: f"C{i}" for i, name in enumerate(EFFECT_NAMES)}
    for o in outcomes:
        colour = "k" if o.kind == "clean" else colours[o.hidden[0]]
        marker = {"single": "o", "clean": "x", "pair": "^"}[o.kind]
        ax1.plot(o.gap_initial, o.gap_final, marker, color=colour, ms=5, alpha=0.8)
    lims = [0.01, 1.2]
    ax1.plot(lims, lims, "k:", lw=0.8)
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xlabel("validation gap, starting model")
    ax1.set_ylabel("validation gap, after the diagnosis")
    ax1.set_title("Gap before and after (o single, ^ two effects, x clean)")
    for name, colour in colours.items():
        ax1.plot([], [], "o", color=colour, label=name)
    ax1.legend(fontsize=7, loc="upper left")
    kinds = [o.hidden[0] if o.hidden else "clean" for o in outcomes]
    labels = [*EFFECT_NAMES, "clean"]
    data = [[o.seconds for o, k in zip(outcomes, kinds, strict=True) if k == lab] for lab in labels]
    ax2.boxplot(data, tick_labels=labels)
    ax2.tick_params(axis="x", rotation=35, labelsize=8)
    ax2.set_ylabel("run time per record [s]")
    ax2.set_title("Run time (single effect / clean; pairs grouped by first effect)")
    fig.tight_layout()
    OUTPUT_DIR.mkdir(exist_ok=True)
    fig.savefig(OUTPUT_DIR / "diagnose.png", dpi=110)
    plt.close(fig)


def mark(ok: bool) -> str:
    return "met" if ok else "**not met**"


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], sys.argv[1:])
    quick = args.quick
    n = 3000 if quick else 5000
    started = time.perf_counter()
    outcomes = [
        run_case(kind, effects, seed, n, input_kind)
        for kind, effects, seed, input_kind in tqdm(cases(quick), desc="diagnose", file=sys.stderr)
    ]
    total = time.perf_counter() - started
    plot(outcomes)

    singles = [o for o in outcomes if o.kind == "single"]
    cleans = [o for o in outcomes if o.kind == "clean"]
    pairs = [o for o in outcomes if o.kind == "pair"]
    rows = []
    for effect in EFFECT_NAMES:
        group = [o for o in singles if o.hidden[0] == effect]
        right = [o for o in group if o.first_right]
        extra = sum(1 for o in group if len(o.named) > 1)
        rows.append(
            [
                f"`{effect}`",
                f"{len(right)} / {len(group)}",
                f"{extra}",
                f"{np.median([o.gap_initial for o in group]):.3f}",
                f"{np.median([o.gap_first for o in group]):.3f}",
                f"{np.median([o.gap_truth for o in group]):.3f}",
                f"{100 * np.median([o.shrink for o in right]):.0f}%" if right else "-",
                f"{100 * np.median([o.excess_closed for o in right]):.0f}%" if right else "-",
                f"{np.median([o.seconds for o in group]):.1f} / "
                f"{max(o.seconds for o in group):.1f}",
            ]
        )
    table = md_table(
        [
            "hidden effect",
            "named first",
            "more named after it",
            "gap start (median)",
            "gap after step 1",
            "gap of the true model",
            "gap shrink",
            "excess over noise closed",
            "time median / max [s]",
        ],
        rows,
    )
    right_share = sum(o.first_right for o in singles) / len(singles)
    clean_ok = sum(not o.named for o in cleans)
    shrinks = [o.shrink for o in singles if o.first_right]
    median_shrink = float(np.median(shrinks)) if shrinks else 0.0
    both = sum(set(o.hidden) <= set(o.named) for o in pairs)
    exact = sum(set(o.hidden) == set(o.named) for o in pairs)
    worst = max(o.seconds for o in outcomes)
    pair_rows = [
        [
            " + ".join(f"`{h}`" for h in o.hidden),
            ", ".join(o.named) or "-",
            f"{o.gap_initial:.3f} -> {o.gap_final:.3f} (truth {o.gap_truth:.3f})",
            f"{o.seconds:.1f}",
        ]
        for o in pairs
    ]
    failures = [
        f"* {o.kind}, hidden {', '.join(o.hidden) or 'nothing'}: named "
        f"{', '.join(o.named) or 'nothing'} (gap {o.gap_initial:.3f} -> {o.gap_final:.3f}, "
        f"truth {o.gap_truth:.3f}); {o.description}"
        for o in outcomes
        if (o.kind == "single" and (not o.first_right or len(o.named) > 1))
        or (o.kind == "clean" and o.named)
        or (o.kind == "pair" and set(o.hidden) != set(o.named))
    ]
    clean_uniform = [o for o in cleans if o.input_kind == "uniform"]
    speed = mark(worst <= 30.0) if n >= 5000 else "not checked (--quick runs N = 3,000)"
    text = f"""## Discrepancy diagnosis

{__doc__.split(chr(10), 3)[3].strip()} {len(outcomes)} records of N = {n:,} samples
({len(singles)} with one effect, {len(cleans)} clean, {len(pairs)} with two effects). Machine:
{machine_description()}. Total {total:.0f} s.

### One hidden effect

"Gap shrink" is ``1 - gap_after / gap_start`` of the first step, over the records where it was
the right effect; the gap cannot fall below the true model's gap (the noise), so "excess over
noise closed" reports ``(gap_start - gap_after) / (gap_start - gap_truth)`` too.

{table}

### Clean records

{clean_ok} of {len(cleans)} clean records had no effect named (median gap
{np.median([o.gap_initial for o in cleans]):.3f}; {len(clean_uniform)} of them with the paper's
i.i.d. uniform input, {sum(not o.named for o in clean_uniform)} of those without a name).

### Two hidden effects

{md_table(["hidden", "named (in order)", "gap", "time [s]"], pair_rows)}

### Records that did not go as hoped

{chr(10).join(failures) if failures else "None."}

![gap before and after, run time](bench/output/diagnose.png)

Command: `{command_line()}`

Targets:
* the right first effect on >= 95% of single-effect records: {mark(right_share >= 0.95)}
  ({100 * right_share:.0f}%, {sum(o.first_right for o in singles)} of {len(singles)})
* no effect named on >= 95% of clean records: {mark(clean_ok >= 0.95 * len(cleans))}
  ({clean_ok} of {len(cleans)})
* median gap shrink >= 60% after the named effect is added: {mark(median_shrink >= 0.6)}
  ({100 * median_shrink:.0f}%)
* both effects named in two-effect records: {mark(both == len(pairs))} ({both} of
  {len(pairs)}; exactly those two, nothing more: {exact} of {len(pairs)})
* <= 30 s for N = 5,000: {speed} (slowest record {worst:.1f} s, median
  {np.median([o.seconds for o in outcomes]):.1f} s at N = {n:,})
"""
    write_section("diagnose", text)


if __name__ == "__main__":
    main()
