"""Discrepancy diagnosis: is the right effect named, nothing on clean data, how far the gap shrinks.

    python bench/diagnose.py [--quick]

Two sets of generated records.

Operation records (``genbacklash_core.diagnose.operation_case``, issue 14): 30 s of a drivetrain
in normal operation (``genbacklash_core.scenarios``): point-to-point moves with trapezoidal
velocity, dwells of 0.1-0.5 s and jogs, 100 Hz position commands held, a 1 kHz encoder quantised
to 4096 counts per revolution with 50 us stamp jitter, white encoder noise of 0-0.5 mrad before
quantisation, 2% of the readings lost (each loss breaks the chain: the sample rule). The play
is 2.6/2.9 degrees scaled by 0.8-1.6, straight branches unless curved. Each effect is hidden at a
random strength: curved branches (0.6-1.6 times the operation drivetrain's quadratic and cubic
terms), a first-order load lag of 3-10 ms after the backlash, a dead time of 3-8 ms, an encoder
offset of 0.15-0.6 rad, both gaps growing 50-150% over the record, an output limit cutting
5-15% of the range the first 70% of the record reaches, a servo lag of 5-20 ms before the
backlash (``input_lag``), and a runout of 0.15-0.4 degrees with a period of 0.25-0.8 rad of
load travel, plus a second harmonic of up to half its size on half the records
(``periodic_error``). ``diagnose(u, y, breaks=...)`` runs with
its defaults (70% estimation, 30% validation) on the samples the node would see.

Paper-style records (``genbacklash_core.diagnose.synthetic_case``), the earlier benchmark, kept
to show the numbers there do not get worse: an ideal backlash (random slope 0.7-1.3, gaps
0.15-0.4) driven by a filtered random walk (AR(1) velocity, reflected at +/-2; every fourth
single-effect and clean record uses the paper's i.i.d. uniform input instead), white output
noise at SNR 20-50, with each of the first six effects hidden at a random strength: cubic
branches, a first- or second-order lag (poles 0.5-0.85, unit static gain), a dead time of 2-8
samples, an output offset larger than the dead zones, a gap growing 50-150% over the record, an
output limit cutting 5-15% of the output range; N = 5,000.
"""

from __future__ import annotations

import os

# one BLAS thread: on a shared machine a multi-threaded BLAS spins against the other processes
# and the 20-parameter least-squares steps of a fit take several times longer
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

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
from genbacklash_core.diagnose.synthetic import OPERATION_EFFECTS, operation_case

SEED = 51_000


class Judged:
    """What both kinds of outcome report: the first name right, the gap shrink."""

    hidden: tuple[str, ...]
    named: tuple[str, ...]
    gap_initial: float
    gap_first: float
    gap_truth: float

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


@dataclass(frozen=True)
class Outcome(Judged):
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


def paper_section(quick: bool) -> str:
    """The paper-style records: the earlier benchmark, as it was."""
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
    return f"""### Paper-style records

{len(outcomes)} records of N = {n:,} samples ({len(singles)} with one effect, {len(cleans)}
clean, {len(pairs)} with two effects; inputs in the description above). Total {total:.0f} s.

#### One hidden effect

"Gap shrink" is ``1 - gap_after / gap_start`` of the first step, over the records where it was
the right effect; the gap cannot fall below the true model's gap (the noise), so "excess over
noise closed" reports ``(gap_start - gap_after) / (gap_start - gap_truth)`` too.

{table}

#### Clean records

{clean_ok} of {len(cleans)} clean records had no effect named (median gap
{np.median([o.gap_initial for o in cleans]):.3f}; {len(clean_uniform)} of them with the paper's
i.i.d. uniform input, {sum(not o.named for o in clean_uniform)} of those without a name).

#### Two hidden effects

{md_table(["hidden", "named (in order)", "gap", "time [s]"], pair_rows)}

#### Records that did not go as hoped

{chr(10).join(failures) if failures else "None."}

![gap before and after, run time](bench/output/diagnose.png)

Targets on these records (the earlier ones; "not worse" is judged against them):
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


# --------------------------------------------------------------------------- operation records

OPERATION_SEED = 14_000
OPERATION_SECONDS = 30.0


@dataclass(frozen=True)
class OperationOutcome(Judged):
    kind: str  # "single", "clean", "pair"
    hidden: tuple[str, ...]  # largest first (by the RMS change of the output it causes)
    sizes: tuple[float, ...]
    named: tuple[str, ...]
    gap_initial: float
    gap_first: float
    gap_final: float
    gap_truth: float  # the true noise-free output's gap: what a perfect model leaves
    floor: float  # the floor diagnose measured (quantisation and noise)
    seconds: float
    samples: int
    description: str

    @property
    def both(self) -> bool:
        return set(self.hidden) <= set(self.named)

    @property
    def in_order(self) -> bool:
        """The hidden effects are first named in the order of their size (an effect named
        again later, say a second raise of the branch degree, does not count)."""
        named: list[str] = []
        for name in self.named:
            if name in self.hidden and name not in named:
                named.append(name)
        return named == list(self.hidden)


def run_operation(kind: str, effects: tuple[str, ...], seed: int) -> OperationOutcome:
    case = operation_case(list(effects), seed, OPERATION_SECONDS)
    sizes = case.sizes()
    order = tuple(sorted(effects, key=lambda e: -sizes[e]))
    started = time.perf_counter()
    result = diagnose(case.u, case.y, breaks=case.breaks)
    seconds = time.perf_counter() - started
    val = result.split.validation
    truth = case.record.x_all[case.record.received]
    y_val = case.y[val]
    gap_truth = float(np.linalg.norm(y_val - truth[val]) / np.linalg.norm(y_val - y_val.mean()))
    first = result.steps[0].gap_after if result.steps else result.gap_initial
    return OperationOutcome(
        kind,
        order,
        tuple(sizes[e] for e in order),
        result.effects,
        result.gap_initial,
        first,
        result.gap_final,
        gap_truth,
        result.floor.gap if result.floor is not None else float("nan"),
        seconds,
        case.u.size,
        case.description,
    )


def operation_cases(quick: bool) -> list[tuple[str, tuple[str, ...], int]]:
    seeds = 2 if quick else 5
    out: list[tuple[str, tuple[str, ...], int]] = []
    seed = OPERATION_SEED
    for effect in OPERATION_EFFECTS:
        for _ in range(seeds):
            out.append(("single", (effect,), seed))
            seed += 1
    for _ in range(2 * seeds):
        out.append(("clean", (), seed))
        seed += 1
    pairs = list(itertools.combinations(OPERATION_EFFECTS, 2))
    for pair in pairs[:: 4 if quick else 1]:
        out.append(("pair", pair, seed))
        seed += 1
    return out


def plot_operation(outcomes: list[OperationOutcome]) -> None:
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.4))
    colours = {name: f"C{i}" for i, name in enumerate(OPERATION_EFFECTS)}
    for o in outcomes:
        colour = "k" if o.kind == "clean" else colours[o.hidden[0]]
        marker = {"single": "o", "clean": "x", "pair": "^"}[o.kind]
        ax1.plot(o.gap_initial / o.floor, o.gap_final / o.floor, marker, color=colour, ms=5)
    lims = [0.5, 1500.0]
    ax1.plot(lims, lims, "k:", lw=0.8)
    ax1.axhline(1.3, color="C3", ls="--", lw=0.8)
    ax1.set_xscale("log")
    ax1.set_yscale("log")
    ax1.set_xlabel("validation gap of the starting model / floor")
    ax1.set_ylabel("validation gap after the diagnosis / floor")
    ax1.set_title("Operation records: gap against the floor (dashed: 1.3 x floor)", fontsize=9)
    for name, colour in colours.items():
        ax1.plot([], [], "o", color=colour, label=name)
    ax1.legend(fontsize=7, loc="upper left")
    kinds = [o.hidden[0] if o.hidden else "clean" for o in outcomes]
    labels = [*OPERATION_EFFECTS, "clean"]
    data = [[o.seconds for o, k in zip(outcomes, kinds, strict=True) if k == lab] for lab in labels]
    ax2.boxplot(data, tick_labels=labels)
    ax2.tick_params(axis="x", rotation=35, labelsize=8)
    ax2.set_ylabel("run time per 30 s record [s]")
    ax2.set_title("Run time (pairs grouped by their larger effect)", fontsize=9)
    fig.tight_layout()
    OUTPUT_DIR.mkdir(exist_ok=True)
    fig.savefig(OUTPUT_DIR / "diagnose_operation.png", dpi=110)
    plt.close(fig)


def operation_section(quick: bool) -> str:
    started = time.perf_counter()
    outcomes = [
        run_operation(kind, effects, seed)
        for kind, effects, seed in tqdm(
            operation_cases(quick), desc="diagnose operation", file=sys.stderr
        )
    ]
    total = time.perf_counter() - started
    plot_operation(outcomes)
    singles = [o for o in outcomes if o.kind == "single"]
    cleans = [o for o in outcomes if o.kind == "clean"]
    pairs = [o for o in outcomes if o.kind == "pair"]
    rows = []
    for effect in OPERATION_EFFECTS:
        group = [o for o in singles if o.hidden[0] == effect]
        right = [o for o in group if o.first_right]
        rows.append(
            [
                f"`{effect}`",
                f"{len(right)} / {len(group)}",
                f"{sum(1 for o in group if len(o.named) > 1)}",
                f"{np.median([o.gap_initial for o in group]):.4f}",
                f"{np.median([o.gap_first for o in group]):.4f}",
                f"{np.median([o.gap_truth for o in group]):.4f}",
                f"{np.median([o.floor for o in group]):.4f}",
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
            "gap of the truth",
            "floor diagnose measured",
            "gap shrink",
            "excess over truth closed",
            "time median / max [s]",
        ],
        rows,
    )
    pair_rows = [
        [
            " + ".join(
                f"`{h}` ({1e3 * size:.2g} mrad)" for h, size in zip(o.hidden, o.sizes, strict=True)
            ),
            ", ".join(o.named) or "-",
            "yes" if o.both else "**no**",
            "yes" if o.in_order else "no",
            f"{o.gap_initial:.4f} -> {o.gap_final:.4f} (truth {o.gap_truth:.4f}, "
            f"floor {o.floor:.4f})",
            f"{o.seconds:.1f}",
        ]
        for o in pairs
    ]
    right_share = sum(o.first_right for o in singles) / len(singles)
    clean_ok = sum(not o.named for o in cleans)
    shrinks = [o.shrink for o in singles if o.first_right]
    median_shrink = float(np.median(shrinks)) if shrinks else 0.0
    both = sum(o.both for o in pairs)
    ordered = sum(o.both and o.in_order for o in pairs)
    exact = sum(set(o.hidden) == set(o.named) for o in pairs)
    worst = max(o.seconds for o in outcomes)
    new = [o for o in singles if o.hidden[0] in ("input_lag", "periodic_error")]
    failures = [
        f"* {o.kind}, hidden {', '.join(o.hidden) or 'nothing'}: named "
        f"{', '.join(o.named) or 'nothing'} (gap {o.gap_initial:.4f} -> {o.gap_final:.4f}, "
        f"truth {o.gap_truth:.4f}, floor {o.floor:.4f}); {o.description}"
        for o in outcomes
        if (o.kind == "single" and (not o.first_right or len(o.named) > 1))
        or (o.kind == "clean" and o.named)
        or (o.kind == "pair" and (set(o.hidden) != set(o.named) or not o.in_order))
    ]
    floor_ratio = [o.floor / o.gap_truth for o in outcomes]
    return f"""### Operation records (issue 14)

{len(outcomes)} records of {OPERATION_SECONDS:g} s at 1 kHz ({len(singles)} with one effect:
{len(singles) // len(OPERATION_EFFECTS)} seeds for each of the {len(OPERATION_EFFECTS)} effects;
{len(cleans)} clean; {len(pairs)} with two effects: every pair of the eight, one seed each),
median {int(np.median([o.samples for o in outcomes])):,} samples after the losses; inputs as
described above, each record's own in the lists below. Total {total:.0f} s.

"Gap of the truth" is the gap the noise-free output of the simulation leaves (what a perfect
model leaves: quantisation and noise); "floor diagnose measured" is diagnose's own estimate of
it from the record (the encoder step and the dwells, `genbacklash_core.diagnose.floor`), the
floor the report states; over all records it is {np.median(floor_ratio):.2f} times the truth's
(median; range {min(floor_ratio):.2f}-{max(floor_ratio):.2f}). "Gap shrink" is
``1 - gap_after / gap_start`` of the first step over the records where it was the right
effect; "excess over truth closed" is ``(gap_start - gap_after) / (gap_start - gap_truth)``.

#### One hidden effect

{table}

#### Clean records

{clean_ok} of {len(cleans)} clean records had no effect named (median gap
{np.median([o.gap_initial for o in cleans]):.4f}, median floor
{np.median([o.floor for o in cleans]):.4f}, median truth
{np.median([o.gap_truth for o in cleans]):.4f}).

#### Two hidden effects

"Size" is the RMS change of the noise-free output when that effect alone is taken out of the
record (same motion, stamps and noise); the larger one is listed first, and "in order" says
whether diagnose named the two in that order.

{md_table(["hidden (size)", "named (in order)", "both", "in order", "gap", "time [s]"], pair_rows)}

#### Records that did not go as hoped

{chr(10).join(failures) if failures else "None."}

![operation records: gap against the floor, run time](bench/output/diagnose_operation.png)

Targets on operation records (issue 14):
* the hidden effect named first on >= 95% of single-effect records, `input_lag` and
  `periodic_error` included: {mark(right_share >= 0.95)} ({100 * right_share:.0f}%,
  {sum(o.first_right for o in singles)} of {len(singles)}; the two new effects
  {sum(o.first_right for o in new)} of {len(new)})
* no effect named on >= 95% of clean records: {mark(clean_ok >= 0.95 * len(cleans))}
  ({clean_ok} of {len(cleans)})
* median gap shrink of the named step >= 60%: {mark(median_shrink >= 0.6)}
  ({100 * median_shrink:.0f}%)
* both effects found in >= 90% of pairs: {mark(both >= 0.9 * len(pairs))} ({both} of
  {len(pairs)}; both and in the order of size: {ordered}; exactly those two: {exact})
* <= 30 s per 30 s record: {mark(worst <= 30.0)} (slowest {worst:.1f} s, median
  {np.median([o.seconds for o in outcomes]):.1f} s)
"""


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], sys.argv[1:])
    quick = args.quick
    operation = operation_section(quick)
    paper = paper_section(quick)
    text = f"""## Discrepancy diagnosis

{__doc__.split(chr(10), 3)[3].strip()}

Machine: {machine_description()}. BLAS limited to one thread (see the script).
Command: `{command_line()}`

{operation}

{paper}
"""
    write_section("diagnose", text)


if __name__ == "__main__":
    main()
