"""Closed-loop benchmark: a simulated drivetrain tracking references with and without compensation.

    python bench/closed_loop.py [--quick]

Two drivetrains: the paper's Example 3 (general backlash followed by linear dynamics) and the
paper's Example 1 backlash alone (curved branches, slopes 0.5-0.6 and far from straight). Each
tracks three references (a sum of sines, smoothed steps, random point-to-point moves) with
four feedforward compensators in front of the motor command:

* uncompensated: a calibrated linear drive (slope and offset of the best straight-line fit of
  the true branches), no play compensation;
* constant gap: the same calibration plus a constant backlash distance added on every
  reversal, i.e. the inverse of the best-fitting *ideal* backlash (what Marlin and LinuxCNC do,
  given their best setting);
* identified online: :class:`InverseBacklash` driven by the estimate of an online identifier
  that runs in the loop on the commands actually sent and the noisy encoder, with confidence
  gating (pass-through until the identifier trusts its estimate);
* oracle: :class:`InverseBacklash` with the true model.

For the cascade the compensator inverts only the backlash; the linear block belongs to the
user's controller, which here is the exact inverse of the true linear block for every method
(a one-step-ahead inverse of ``y(t) = x(t-1) + 0.15 x(t-2) + 0.2 y(t-1) - 0.35 y(t-2)``), so the
methods differ only in how they handle the play. The controller adds integral feedback on
the noisy encoder; the motor has a speed limit; every run starts with a commissioning
experiment (random motor moves) before tracking. Tracking error: ``r - y`` on the noise-free
output; the identifier sees the output with white noise at the example's SNR. The report
(``bench/output/closed_loop.md``) states every setting.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
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

from genbacklash_core import (
    Cascade,
    CompensatorOptions,
    GenBacklashError,
    GeneralBacklash,
    InverseBacklash,
    WindowedIdentifier,
    WindowedSettings,
    paper_example,
)

SEED = 20261121
CHUNK = 20  # samples per online step: identifier update, then compensator model swap
COMMISSIONING = 5000  # samples of the identification experiment before tracking
IDENTIFIER_SETTINGS = WindowedSettings(window=5000, refine=True, iterations=1)
KI = 0.05  # integral gain of the feedback on the encoder (per sample)
WARM_UP = 0.1  # leading share of each run left out of the steady-state RMS


@dataclass(frozen=True)
class Drivetrain:
    """A simulated drivetrain: the true model, its command travel and the encoder's SNR."""

    name: str
    model: GeneralBacklash | Cascade
    u_max: float
    snr: float

    @property
    def max_rate(self) -> float:
        """The motor's speed limit per sample: crossing the whole gap takes 5 samples."""
        return (self.backlash.c_left + self.backlash.c_right) / 5.0

    @property
    def backlash(self) -> GeneralBacklash:
        return self.model.backlash if isinstance(self.model, Cascade) else self.model

    @property
    def orders(self) -> tuple[int, int]:
        if isinstance(self.model, Cascade):
            return self.model.linear.na, self.model.linear.nb
        return 0, 0


def drivetrains() -> list[Drivetrain]:
    ex3, ex1 = paper_example(3), paper_example(1)
    return [
        Drivetrain("Example 3 cascade", ex3.model, ex3.u_max, ex3.snr),
        Drivetrain("Example 1 curved-branch backlash", ex1.model, ex1.u_max, ex1.snr),
    ]


# --------------------------------------------------------------------------- references


def _smoothstep(s: np.ndarray) -> np.ndarray:
    s = np.clip(s, 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def _moves(
    rng: np.random.Generator,
    n: int,
    levels: Callable[[], float],
    hold: tuple[int, int],
    travel: tuple[int, int],
) -> np.ndarray:
    """Point-to-point moves with smoothstep profiles between random levels."""
    r = np.empty(n)
    t, level = 0, 0.0
    while t < n:
        dwell = int(rng.integers(*hold))
        r[t : t + dwell] = level
        t += dwell
        target, length = levels(), int(rng.integers(*travel))
        ramp = level + (target - level) * _smoothstep(np.arange(1, length + 1) / length)
        r[t : t + length] = ramp[: max(0, min(length, n - t))]
        t += length
        level = target
    return r


def references(n: int, amplitude: float, rng: np.random.Generator) -> dict[str, np.ndarray]:
    t = np.arange(n)
    sines = amplitude * (0.6 * np.sin(2 * np.pi * t / 400) + 0.4 * np.sin(2 * np.pi * t / 143 + 1))
    steps = _moves(
        rng, n, lambda: amplitude * rng.choice([-1.0, -0.5, 0.0, 0.5, 1.0]), (200, 400), (40, 41)
    )
    moves = _moves(rng, n, lambda: amplitude * rng.uniform(-1, 1), (0, 150), (30, 300))
    return {"sines": sines, "steps": steps, "random moves": moves}


# --------------------------------------------------------------------------- the plant


class Plant:
    """The drivetrain, one sample at a time: motor speed limit, backlash, linear block."""

    def __init__(self, drivetrain: Drivetrain) -> None:
        bl = drivetrain.backlash
        self.m_left, self.m_right = bl.m_left[::-1], bl.m_right[::-1]
        self.c_left, self.c_right = bl.c_left, bl.c_right
        self.max_rate = drivetrain.max_rate
        lin = drivetrain.model.linear if isinstance(drivetrain.model, Cascade) else None
        self.a = lin.a if lin is not None else ()
        self.b = lin.b if lin is not None else ()
        self.xs = [0.0] * (len(self.a) + 1)  # x(t-1), x(t-2), ...
        self.ys = [0.0] * (len(self.b) + 1)  # y(t-1), y(t-2), ...
        self.motor = 0.0
        self.x = 0.0

    @staticmethod
    def _branch(m_reversed: tuple[float, ...], xi: float) -> float:
        acc = 0.0
        for coefficient in m_reversed:  # Horner, eqs. (11)-(12)
            acc = (acc + coefficient) * xi
        return acc

    def step(self, command: float) -> float:
        """Apply one command; return the noise-free output."""
        self.motor += min(max(command - self.motor, -self.max_rate), self.max_rate)
        left = self._branch(self.m_left, self.motor + self.c_left)
        right = self._branch(self.m_right, self.motor - self.c_right)
        self.x = min(max(self.x, min(left, right)), max(left, right))  # eq. (20)
        if not self.a:
            return self.x
        y = sum(ai * self.xs[i] for i, ai in enumerate(self.a))  # eq. (30): x(t-1), ...
        y -= sum(bj * self.ys[j] for j, bj in enumerate(self.b))
        self.xs = [self.x, *self.xs[:-1]]
        self.ys = [y, *self.ys[:-1]]
        return y


def desired_backlash_output(drivetrain: Drivetrain, r: np.ndarray) -> np.ndarray:
    """The user's controller: ``x_d`` such that the linear block's output is ``r`` (exact)."""
    if not isinstance(drivetrain.model, Cascade):
        return r.copy()
    lin = drivetrain.model.linear
    # y(t) = sum a_i x(t-i) - sum b_j y(t-j)  =>  x(t-1) = [B(q) y](t) - sum_{i>=2} a_i x(t-i)
    ahead = np.concatenate([r[1:], r[-1:]])  # r(t + 1): the planned trajectory is known
    b_poly = np.concatenate([[1.0], lin.b])
    x_d = np.zeros_like(r)
    for t in range(r.size):
        acc = sum(bj * (ahead[t - j] if t - j >= 0 else 0.0) for j, bj in enumerate(b_poly))
        acc -= sum(ai * x_d[t - i + 1] for i, ai in enumerate(lin.a[1:], 2) if t - i + 1 >= 0)
        x_d[t] = acc
    return x_d


# --------------------------------------------------------------------------- compensators


def straight_line_fit(backlash: GeneralBacklash, u_max: float) -> tuple[float, float, float]:
    """Common slope ``m`` and offsets of the best straight lines through the two branches.

    Returns ``(m, c_left, c_right)`` of the ideal backlash ``L = m (u + c_L)``,
    ``R = m (u - c_R)`` closest to the true branches over ``|u| <= u_max``.
    """
    grid = np.linspace(-u_max, u_max, 401)
    ones, zeros = np.ones_like(grid), np.zeros_like(grid)
    design = np.block(
        [
            [grid[:, None], ones[:, None], zeros[:, None]],
            [grid[:, None], zeros[:, None], ones[:, None]],
        ]
    )
    target = np.concatenate([backlash.left(grid), backlash.right(grid)])
    m, off_left, off_right = np.linalg.lstsq(design, target, rcond=None)[0]
    return float(m), float(off_left / m), float(-off_right / m)


@dataclass
class LoopResult:
    """One closed-loop run: noise-free output and the online identifier's trace."""

    y: np.ndarray
    trace: list[tuple[int, float, str]]
    seconds: float


def commissioning(drivetrain: Drivetrain, rng: np.random.Generator) -> np.ndarray:
    """Motor commands of the identification experiment run before tracking starts.

    Random levels in 90% of the command travel, each held 2 samples and approached at the
    motor's speed limit, then back to 0: the rich input the paper's method needs (the
    cascade's equation error is ill-conditioned on smooth inputs such as the references).
    """
    levels = rng.uniform(-0.9, 0.9, COMMISSIONING // 2) * drivetrain.u_max
    wanted = np.concatenate([np.repeat(levels, 2), np.zeros(100)])
    commands = np.empty_like(wanted)
    motor = 0.0
    for t, target in enumerate(wanted):  # within the motor's speed limit: command = motor
        motor += min(max(target - motor, -drivetrain.max_rate), drivetrain.max_rate)
        commands[t] = motor
    return commands


def run_loop(
    drivetrain: Drivetrain,
    r: np.ndarray,
    method: str,
    noise: np.ndarray,
    commands: np.ndarray,
) -> LoopResult:
    """Commissioning ``commands``, then track ``r``: feedforward + integral feedback on the
    noisy encoder, mapped to the motor command by the method.

    ``x_d(t) = x_ff(t) + KI * sum_{k<t} (r(k) - y_meas(k))`` where ``x_ff`` is the user's
    controller's exact feedforward. ``r`` and ``noise`` cover the whole run; ``r`` is ignored
    during commissioning.
    """
    x_ff = desired_backlash_output(drivetrain, r)
    n = r.size
    n_c = commands.size
    plant = Plant(drivetrain)
    m, c_left, c_right = straight_line_fit(drivetrain.backlash, drivetrain.u_max)
    options = CompensatorOptions(max_rate=drivetrain.max_rate)
    comp: InverseBacklash | None = None
    ident: WindowedIdentifier | None = None
    if method == "oracle":
        comp = InverseBacklash(drivetrain.backlash, options)
    elif method == "constant gap":
        comp = InverseBacklash(GeneralBacklash.ideal(m, c_left, c_right), options)
    elif method == "identified online":
        na, nb = drivetrain.orders
        ident = WindowedIdentifier(drivetrain.backlash.degree, na, nb, settings=IDENTIFIER_SETTINGS)
        comp = InverseBacklash(GeneralBacklash.ideal(1.0, 1e-3, 1e-3), options)  # placeholder
    midline = m * (c_left - c_right) / 2.0
    y = np.zeros(n)
    u_sent = np.zeros(n)
    y_meas = np.zeros(n)
    trace: list[tuple[int, float, str]] = []
    confidence = 0.0
    integral = 0.0
    t_start = time.perf_counter()
    for t in range(n):
        if t > n_c:
            integral += KI * (r[t - 1] - y_meas[t - 1])
        x_d = x_ff[t] + integral
        if t < n_c:
            u = commands[t]
        elif comp is None:
            u = (x_d - midline) / m  # calibrated linear drive
        else:
            u = comp.step(x_d, confidence if ident is not None else 1.0)
        u_sent[t] = u
        y[t] = plant.step(u)
        y_meas[t] = y[t] + noise[t]
        if ident is not None and (t + 1) % CHUNK == 0:
            est = ident.update_many(u_sent[t + 1 - CHUNK : t + 1], y_meas[t + 1 - CHUNK : t + 1])
            confidence = 0.0
            if (model := est.model) is not None:
                try:
                    comp.set_model(model)  # type: ignore[union-attr]
                    confidence = est.confidence
                except GenBacklashError:  # an estimate the inverse cannot use: pass through
                    confidence = 0.0
            trace.append((t + 1, confidence, est.state.value))
    return LoopResult(y, trace, time.perf_counter() - t_start)


# --------------------------------------------------------------------------- the benchmark

METHODS = ("uncompensated", "constant gap", "identified online", "oracle")


def rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e * e)))


def main() -> None:
    args = parse_args(__doc__.splitlines()[0], sys.argv[1:])
    n = 4000 if args.quick else 20_000
    rng = np.random.default_rng(SEED)
    results = []
    started = time.perf_counter()
    cases = [(d, name) for d in drivetrains() for name in ("sines", "steps", "random moves")]
    progress = tqdm(total=len(cases), desc="closed loop", file=sys.stderr)
    for drivetrain in drivetrains():
        reach = min(
            abs(float(drivetrain.backlash.left(-drivetrain.u_max)[()])),
            abs(float(drivetrain.backlash.right(drivetrain.u_max)[()])),
        )
        refs = references(n, 0.7 * reach, rng)
        for ref_name, ref in refs.items():
            commands = commissioning(drivetrain, rng)
            n_c = commands.size
            r = np.concatenate([np.zeros(n_c), ref])
            # the same encoder noise for every method: std of the output / the example's SNR
            noise = rng.normal(0.0, float(np.std(ref)) / drivetrain.snr, r.size)
            runs = {m: run_loop(drivetrain, r, m, noise, commands) for m in METHODS}
            outputs = {m: run.y[n_c:] for m, run in runs.items()}
            trace = runs["identified online"].trace  # sample counts from the start of the run
            online_seconds = runs["identified online"].seconds / r.size  # per sample
            steady = int(WARM_UP * n)
            r = ref
            errors = {m: r - outputs[m] for m in METHODS}
            whole = {m: rms(errors[m]) for m in METHODS}
            late = {m: rms(errors[m][steady:]) for m in METHODS}
            trusted = next((stop for stop, conf, _ in trace if conf >= 0.5), None)
            results.append((drivetrain, ref_name, r, outputs, late, whole, trusted, online_seconds))
            progress.update()
    progress.close()
    write_report(n, results, time.perf_counter() - started)


def write_report(n: int, results: list, seconds: float) -> None:
    OUTPUT_DIR.mkdir(exist_ok=True)
    steady = int(WARM_UP * n)
    rows = []
    verdicts = {"reduction": [], "oracle": [], "constant": []}
    for drivetrain, ref_name, _r, _outputs, late, whole, trusted, online_seconds in results:
        reduction = 1.0 - late["identified online"] / late["uncompensated"]
        vs_oracle = late["identified online"] / late["oracle"]
        vs_constant = late["constant gap"] / late["identified online"]
        verdicts["reduction"].append(reduction >= 0.90)
        verdicts["oracle"].append(vs_oracle <= 1.1)
        verdicts["constant"].append(vs_constant >= 3.0)
        rows.append(
            [
                drivetrain.name,
                ref_name,
                *(f"{late[m]:.2e}" for m in METHODS),
                f"{whole['identified online']:.2e}",
                f"{100 * reduction:.1f}%",
                f"{vs_oracle:.3f}",
                f"{vs_constant:.1f}x",
                "never" if trusted is None else f"{trusted:,}",
                f"{1e6 * online_seconds:.0f} µs",
            ]
        )
    headers = [
        "drivetrain",
        "reference",
        *(f"RMS {m}" for m in METHODS),
        "RMS online, whole run",
        "online: reduction vs uncompensated",
        "online / oracle",
        "constant gap / online",
        "confidence >= 0.5 after",
        "loop cost per sample (identify + compensate + plant)",
    ]

    def verdict(key: str) -> str:
        hits = verdicts[key]
        return f"{'met' if all(hits) else '**not met**'} ({sum(hits)} of {len(hits)} runs)"

    plot_results(results, n)
    text = f"""## Closed loop: tracking with and without backlash compensation

What is measured: RMS tracking error ``r - y`` (noise-free output) of a simulated drivetrain
over {n:,} tracking samples per run, after a warm-up of the first {steady:,} (the
identified-online column also gives the whole tracking part). Every run starts with the same
{COMMISSIONING:,}-sample commissioning experiment (random motor moves within the speed limit,
no tracking), during which the online identifier learns; it keeps learning while tracking.
Drivetrains: the paper's Example 3 (general backlash + linear block; the user's controller
inverts the true linear block exactly, one step ahead, for every method) and the paper's
Example 1 backlash alone (curved branches). The motor has a speed limit (the whole gap takes 5
samples to cross), so even the oracle errs briefly at each reversal. Controller: that
feedforward plus integral feedback (gain {KI} per sample) on the encoder, which carries white
noise at the example's SNR. References: a sum of two sines, smoothed steps between five
levels, random point-to-point moves (seeded). Methods, mapping the controller's desired
backlash output to the motor command:
*uncompensated*, a calibrated linear drive (the common slope and midline of the best
straight-line fit of both true branches over the command travel); *constant gap*, that
calibration plus a constant backlash distance on every reversal (the inverse of the
best-fitting ideal backlash: what Marlin and LinuxCNC do with their best setting);
*identified online*, `InverseBacklash` (default gating: full correction from confidence 0.5)
given every {CHUNK} samples the estimate of a `WindowedIdentifier` with
`{IDENTIFIER_SETTINGS}` that runs in the loop on the commands actually sent and the noisy
encoder; *oracle*, `InverseBacklash` with the true model. "confidence >= 0.5 after" counts
samples from the start of the run, commissioning included. Machine: {machine_description()}.
Total {seconds:.0f} s.

{md_table(headers, rows)}

Command: `{command_line()}`

![closed-loop tracking](bench/output/closed_loop.png)

Targets (on the steady-state RMS):
* RMS tracking error down >= 90% vs uncompensated: {verdict("reduction")}
* identified online within 1.1x of the oracle: {verdict("oracle")}
* >= 3x better than the constant-gap compensator (both drivetrains have curved branches):
  {verdict("constant")}
"""
    write_section("closed_loop", text)


def plot_results(results: list, n: int) -> None:
    fig, axes = plt.subplots(2, 2, figsize=(12, 7))
    for row, drivetrain_name in enumerate(dict.fromkeys(r[0].name for r in results)):
        case = next(r for r in results if r[0].name == drivetrain_name and r[1] == "sines")
        _, _, ref, outputs, *_ = case
        window = slice(n - 800, n)
        ax = axes[row, 0]
        ax.plot(ref[window], "k", lw=1.5, label="reference")
        for method in METHODS:
            ax.plot(outputs[method][window], lw=1, label=method)
        ax.set_title(f"{drivetrain_name}: sines, last 800 samples")
        ax.legend(fontsize=7)
        ax = axes[row, 1]
        refs = [r for r in results if r[0].name == drivetrain_name]
        width = 0.2
        for k, method in enumerate(METHODS):
            ax.bar(
                np.arange(len(refs)) + k * width, [r[4][method] for r in refs], width, label=method
            )
        ax.set_xticks(np.arange(len(refs)) + 1.5 * width, [r[1] for r in refs])
        ax.set_yscale("log")
        ax.set_ylabel("steady-state RMS error")
        ax.set_title(f"{drivetrain_name}: RMS tracking error")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUTPUT_DIR / "closed_loop.png", dpi=110)
    plt.close(fig)


if __name__ == "__main__":
    main()
