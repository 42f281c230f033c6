"""Normal operation: the node on a drivetrain that moves, dwells and reverses (issue 12).

    python bench/operation.py [--quick]

Inputs (``genbacklash_core.scenarios.operation_record``, seeds 0-4 unless said): 60 s of
point-to-point moves with trapezoidal velocity (v_max 3 rad/s, a_max 30 rad/s^2), dwells of
0.1-0.5 s and jogs (half the moves reverse the previous one); position commands at 100 Hz
(0-0.2 ms late) held by the drivetrain; a 1 kHz encoder quantised to 4096 counts/rev, stamps
jittered by 50 us (sd), 2 % of the readings lost; the mildly curved backlash
``OPERATION_BACKLASH`` (c_L 0.045 rad, c_R 0.05 rad, i.e. 2.6 and 2.9 degrees of play).

Everything goes through ``BacklashPipeline`` (the node's one pipeline, default parameters,
each identifier) message by message, as a replay of the bag would. Measured:

* the data time of the first published estimate, from the first command;
* the final estimate's free-run NRMSE against the noise-free truth (the true drivetrain
  simulated on the held commands at every sampling instant, lost readings included);
* the compensated commands the node published, applied to the true drivetrain: the RMS load
  tracking error (load minus command) over the second half, against the uncompensated one;
* the pipeline's cost per encoder message and the identifier's own cost per sample;
* wear: the gap widening by 50 % over 10 minutes of operation, the identifier fed in node
  batches; the lag of the estimated c_L behind the truth over the second half;
* loss: Example 1 (one reading per command, SNR 25) and the operation scenario (ten readings
  per command) with 0/2/10/30 % of the readings lost at random, the sample rule on.
"""

from __future__ import annotations

import sys
import time
from typing import Any

import numpy as np
from _common import command_line, machine_description, md_table, parse_args, write_section
from tqdm import tqdm

from genbacklash_core import (
    GeneralBacklash,
    RecursiveIdentifier,
    WindowedIdentifier,
    nrmse,
    paper_example,
)
from genbacklash_core.samples import bridge_lost, sample_breaks
from genbacklash_core.scenarios import (
    OperationRecord,
    OperationSettings,
    operation_record,
    simulate_worn,
)
from genbacklash_ros.bags.simbags import feed_record
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.pipeline import BacklashPipeline

RECEIVE_DELAY_NS = 200_000  # encoder readings reach the node 0.2 ms after their stamp
METHODS = ("windowed", "recursive")
BATCH = 64


def true_load(rec: OperationRecord, u: np.ndarray) -> np.ndarray:
    """The true drivetrain (wear included) driven by ``u`` at every sampling instant."""
    return simulate_worn(rec.settings.model, u, float(rec.x_all[0]), rec.c_left, rec.c_right)


def run_pipeline(rec: OperationRecord, method: str, **extra: str) -> dict[str, Any]:
    """Replay the record through the node's pipeline (``extra``: more node parameters, e.g.
    ``servo_model="auto"``); what it published, judged."""
    params = NodeParameters(command_type="float64", encoder_type="float64", method=method, **extra)
    pipe = BacklashPipeline(params)
    t0 = time.perf_counter()
    fed = feed_record(pipe, rec, RECEIVE_DELAY_NS)
    pipe.finish()
    cost = (time.perf_counter() - t0) / rec.encoder_t_ns.size
    sent, first_estimate = fed.sent, fed.first_estimate_s
    est = pipe.estimate
    model = est.model
    fit, play = float("inf"), float("nan")
    if isinstance(model, GeneralBacklash):
        fit = nrmse(rec.x_all, model.simulate(rec.u_all, rec.x_all[0]))
        play = model.c_left + model.c_right
    k = np.searchsorted(rec.command_t_ns, rec.sample_t_ns, side="right") - 1
    load_comp = true_load(rec, sent[k])
    half = rec.sample_t_ns >= rec.sample_t_ns[-1] / 2
    desired = rec.u_all
    rms_raw = float(np.sqrt(np.mean((rec.x_all - desired)[half] ** 2)))
    rms_comp = float(np.sqrt(np.mean((load_comp - desired)[half] ** 2)))
    return {
        "first": float("nan") if first_estimate is None else first_estimate,
        "nrmse": fit,
        "rms_raw": rms_raw,
        "rms_comp": rms_comp,
        "cut": 1.0 - rms_comp / rms_raw,
        "cost_us": cost * 1e6,
        "state": est.state.value,
        "play": play,
        "servo": pipe.servo,
        "seconds": cost * rec.encoder_t_ns.size,
    }


def identifier(method: str, degree: int = 3) -> WindowedIdentifier | RecursiveIdentifier:
    if method == "recursive":
        return RecursiveIdentifier(degree)
    return WindowedIdentifier(degree)


def identifier_cost(rec: OperationRecord, method: str) -> float:
    u, y, b = rec.series()
    ident = identifier(method)
    t0 = time.perf_counter()
    for s in range(0, u.size, BATCH):
        ident.update_many(u[s : s + BATCH], y[s : s + BATCH], b[s : s + BATCH])
    return (time.perf_counter() - t0) / u.size * 1e6


def wear_lag(method: str, seed: int, minutes: float) -> tuple[float, float]:
    rec = operation_record(OperationSettings(duration=60.0 * minutes, wear=0.5), seed)
    u, y, b = rec.series()
    t = rec.encoder_t_ns / 1e9
    truth = rec.c_left[rec.received]
    ident = identifier(method)
    lags = []
    for s in range(0, u.size, 1000):
        est = ident.update_many(u[s : s + 1000], y[s : s + 1000], b[s : s + 1000])
        now = t[min(s + 1000, u.size) - 1]
        if now > t[-1] / 2 and est.available:
            k = min(int(np.searchsorted(truth, est.parameters[3])), t.size - 1)
            lags.append(now - t[k])
    final = ident.estimate
    return float(np.median(lags)) if lags else float("nan"), float(
        abs(final.parameters[3] - truth[-1]) if final.available else float("nan")
    )


def loss_error(method: str, kind: str, rate: float, seed: int, bridge: bool) -> tuple[float, float]:
    """Final max parameter error and signed c_L error (the bias loss used to cause).

    ``bridge``: lift the breaks of lost readings along a monotone input
    (:func:`~genbacklash_core.samples.bridge_lost`, the node's rule for a backlash alone);
    otherwise every lost reading breaks the chain.
    """
    if kind == "example1":
        ex = paper_example(1)
        d = ex.generate(seed, n_samples=6000)
        truth = ex.model.parameters()
        keep = np.random.default_rng([seed, 5]).random(d.u.size) >= rate
        keep[0] = True
        u, y = d.u[keep], d.y[keep]
        b = sample_breaks(np.flatnonzero(keep) * 1_000_000, 1e6)
        if bridge:
            b = bridge_lost(b, d.u, np.flatnonzero(keep))
    else:
        rec = operation_record(OperationSettings(duration=60.0, loss=rate), seed)
        u, y, b = rec.series(bridge=bridge)
        truth = rec.truth.parameters()
    ident = identifier(method)
    for s in range(0, u.size, BATCH):
        ident.update_many(u[s : s + BATCH], y[s : s + BATCH], b[s : s + BATCH])
    est = ident.refit()
    if not est.available:
        return float("inf"), float("inf")
    n = ident.structure.degree
    return float(np.max(np.abs(est.parameters - truth))), float(est.parameters[n] - truth[n])


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], sys.argv[1:])
    seeds = range(2) if args.quick else range(5)
    duration = 20.0 if args.quick else 60.0
    minutes = 3.0 if args.quick else 10.0
    loss_seeds = range(2) if args.quick else range(6)
    rows = []
    for method in METHODS:
        for seed in tqdm(seeds, desc=f"operation, {method}", file=sys.stderr):
            rec = operation_record(OperationSettings(duration=duration), seed)
            r = run_pipeline(rec, method)
            r["ident_us"] = identifier_cost(rec, method)
            rows.append((method, seed, r))
    table = md_table(
        [
            "identifier",
            "seed",
            "first estimate (s)",
            "final state",
            "free-run NRMSE vs truth",
            "RMS error uncompensated (rad)",
            "compensated (rad)",
            "cut",
            "pipeline us/encoder msg",
            "identifier us/sample",
        ],
        [
            (
                m,
                s,
                f"{r['first']:.2f}",
                r["state"],
                f"{r['nrmse']:.5f}",
                f"{r['rms_raw']:.4f}",
                f"{r['rms_comp']:.4f}",
                f"{100 * r['cut']:.1f}%",
                f"{r['cost_us']:.1f}",
                f"{r['ident_us']:.2f}",
            )
            for m, s, r in rows
        ],
    )
    wear_rows = []
    for method in METHODS:
        for seed in tqdm(seeds, desc=f"wear, {method}", file=sys.stderr):
            lag, final = wear_lag(method, seed, minutes)
            wear_rows.append((method, seed, f"{lag:.1f}", f"{final:.4f}"))
    wear_table = md_table(
        ["identifier", "seed", "median lag of c_L, 2nd half (s)", "final |c_L error| (rad)"],
        wear_rows,
    )
    loss_rows = []
    for method in METHODS:
        for kind in ("example1", "operation"):
            for bridge in (False, True):
                errors, biases = {}, {}
                for rate in (0.0, 0.02, 0.1, 0.3):
                    values = [loss_error(method, kind, rate, s, bridge) for s in loss_seeds]
                    errors[rate] = float(np.mean([v[0] for v in values]))
                    biases[rate] = float(np.mean([v[1] for v in values]))
                base = errors[0.0]
                loss_rows.append(
                    (
                        method,
                        "Example 1, 1 reading/command"
                        if kind == "example1"
                        else "operation, 10 readings/command",
                        "bridged (default)" if bridge else "strict",
                        *(
                            f"{errors[r]:.3g} ({errors[r] / base:.2f}x; c_L {biases[r]:+.1g})"
                            for r in errors
                        ),
                    )
                )
    loss_table = md_table(
        ["identifier", "input", "rule", "0 % loss", "2 %", "10 %", "30 %"],
        loss_rows,
    )
    text = f"""## Normal operation (issue 12)

`{command_line()}`; machine: {machine_description()}.

{__doc__.split(chr(10), 3)[3].strip()}

### Through the node's pipeline, {duration:g} s records

{table}

Targets: first estimate within 10 s; final NRMSE <= 0.02; compensation cuts the RMS tracking
error by >= 85 % over the second half; identifier <= 20 us/sample.

### Wear: gap +50 % over {minutes:g} minutes of operation (target: lag <= 30 s)

{wear_table}

### Lost readings (target: final error <= 1.2x the error without loss)

Each cell: the final max parameter error (mean over {len(loss_seeds)} seeds), its ratio to no
loss, and the mean signed error of c_L (what loss used to bias: both gaps ~15 % small at 30 %
loss, i.e. c_L -0.1 on Example 1). Two sample rules: *strict*, every lost reading breaks the
chain (a row needs both readings of a pair); *bridged*, the breaks of up to
`MAX_BRIDGED` lost readings are lifted where the input over them was monotone
(`genbacklash_core.samples.bridge_lost`: a backlash alone is rate independent, so the readings
around such a gap are consecutive states), the node's rule for `model: backlash`. At ten
readings per held command nearly every lost reading is bridged and the 30 % case keeps every
informative row (strict: about half); on Example 1's random input a third of single losses
are. The operation scenario's errors are ~1e-4 rad, a tenth of an encoder count (1.5e-3
rad), so its strict ratios scatter with the number of rows kept.

{loss_table}
"""
    path = write_section("operation", text)
    print(f"wrote {path}", file=sys.stderr)


if __name__ == "__main__":
    main()
