"""The position servo between the command and the gear: a dead time and a first-order lag.

The paper's play operator (eq. 8, in its one-equation form eq. 20) takes the gear's input
``u(t)`` to be the command. On a drivetrain the command is a *setpoint* of a position servo
that answers it milliseconds later, so the gear's input is the servo's output, not the command
(issue 23). Without a motor encoder the servo's output is not measured; it is modelled here
by the simplest structure that describes a fast position loop:

* a dead time ``D`` (the ``time_delay`` structure of :mod:`genbacklash_core.diagnose`): the
  servo's target at time ``t`` is the command in force at ``t - D``,
  ``r(t) = u(t - D)``;
* a first-order lag of time constant ``T`` (``input_lag``): ``T dx/dt = r(t) - x(t)``.

The commands are *held* (zero-order hold), so ``r`` is piecewise constant and the lag has a
closed form on each segment: with ``r = v`` from event ``s_j`` to the next,

    ``x(t) = v + (x(s_j) - v) exp(-(t - s_j) / T)``,    ``s_j <= t <= s_{j+1}``    (S1)

(the exact solution of the lag's ODE; ``T = 0`` gives ``x(t) = v``, the dead time alone). The
events are the command changes shifted by ``D``; the recursion (S1) runs once per command
change, and each sample is evaluated from the event before it, so the output is exact at
every encoder stamp whatever the stamps' jitter. The play operator (eq. 8/20) is then applied
to ``x`` in place of ``u``; its parameters (eq. 23) keep their meaning: ``c_L + c_R`` is the
play on the servo's output, the motor side.

When a command changed is taken from the samples themselves (the first sample holding a new
value), not from the commands' own stamps: a CSV of readings holds no command stamps, and a
bag of the same readings must give the same rows (the settling rule,
:mod:`genbacklash_core.settling`, reads the changes the same way). The change is then dated
up to one encoder period late, a bias the estimated dead time absorbs.

Before the first event the servo is taken at rest at the first command.

:func:`estimate_servo` chooses ``(D, T)`` with the play: a coarse grid then a local
refinement, each candidate scored by the free-run misfit of the backlash identified on the
candidate's modelled input (:func:`~genbacklash_core.identify.backlash_misfit`: what
:func:`~genbacklash_core.identify.identify_backlash` reads without refinement, eqs. 22-29).
The lag's recursion (S1) runs once per time constant tried, not once per candidate: from the
stream's start the outputs at the events do not depend on the dead time (``_Outputs``).

Examples
--------
>>> import numpy as np
>>> t = np.arange(6) * 1_000_000  # 1 kHz
>>> u = np.array([0.0, 0.0, 1.0, 1.0, 1.0, 1.0])  # a step at 2 ms
>>> x, _ = ServoModel(0.001, 0.0).output(t, u)  # a 1 ms dead time
>>> x.tolist()
[0.0, 0.0, 0.0, 1.0, 1.0, 1.0]
>>> x, _ = ServoModel(0.0, 0.001).output(t, u)  # a 1 ms lag: 1 - exp(-k)
>>> np.round(x, 4).tolist()
[0.0, 0.0, 0.0, 0.6321, 0.8647, 0.9502]
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ._typing import ArrayLike, BoolArray, FloatArray
from .errors import GenBacklashError

__all__ = [
    "DEAD_TIMES",
    "TIME_CONSTANTS",
    "ServoFit",
    "ServoModel",
    "ServoState",
    "estimate_servo",
    "servo_changes",
]

#: The coarse grid of :func:`estimate_servo` (s): dead times, then time constants.
DEAD_TIMES: tuple[float, ...] = (0.0, 0.002, 0.004, 0.006, 0.009, 0.013, 0.018)
TIME_CONSTANTS: tuple[float, ...] = (0.0, 0.002, 0.004, 0.007, 0.011, 0.016, 0.024, 0.035)
_REFINE_ROUNDS = 6  # halvings of the step of the compass search (2 ms grid: to 0.016 ms)


@dataclass(frozen=True)
class ServoState:
    """What :meth:`ServoModel.output` carries from one piece of a stream to the next.

    Attributes
    ----------
    last_u : float or None
        The command of the last sample (None: no sample yet).
    anchor_ns : int or None
        The last event at or before the last sample (None: none yet).
    anchor_x : float
        The servo's output at ``anchor_ns`` (S1).
    anchor_v : float
        The target in force from ``anchor_ns``.
    pending : tuple of (int, float)
        Events after the last sample: ``(time, target)``, the changes still inside the
        dead time.
    """

    last_u: float | None = None
    anchor_ns: int | None = None
    anchor_x: float = math.nan
    anchor_v: float = math.nan
    pending: tuple[tuple[int, float], ...] = field(default=())


@dataclass(frozen=True)
class ServoModel:
    """A dead time and a first-order lag (see the module notes), in seconds.

    ``ServoModel(0, 0)`` is no servo: the gear's input is the command.

    >>> ServoModel(-0.001, 0.0)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: servo dead_time must be finite and >= 0 ...
    """

    dead_time: float = 0.0
    time_constant: float = 0.0

    def __post_init__(self) -> None:
        for name in ("dead_time", "time_constant"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int | float):
                raise GenBacklashError(f"servo {name} must be a number, got {value!r}")
            if not math.isfinite(value) or value < 0 or value > 10.0:
                raise GenBacklashError(f"servo {name} must be finite and >= 0 (s), got {value!r}")
            object.__setattr__(self, name, float(value))

    @property
    def is_identity(self) -> bool:
        """No dead time and no lag: the servo's output is the command."""
        return self.dead_time == 0.0 and self.time_constant == 0.0

    @property
    def dead_ns(self) -> int:
        """The dead time in integer nanoseconds."""
        return round(self.dead_time * 1e9)

    @property
    def tau_ns(self) -> float:
        """The lag's time constant in nanoseconds (0 under a nanosecond: no lag at the
        stamps' resolution)."""
        tau_ns = self.time_constant * 1e9
        return tau_ns if tau_ns >= 1.0 else 0.0

    def to_dict(self) -> dict[str, float]:
        """``{"dead_time": s, "time_constant": s}`` (the JSON of identify and replay)."""
        return {"dead_time": self.dead_time, "time_constant": self.time_constant}

    def output(
        self, times_ns: ArrayLike, us: ArrayLike, state: ServoState | None = None
    ) -> tuple[FloatArray, ServoState]:
        """The modelled servo output at each sample, and the state after them.

        Parameters
        ----------
        times_ns : array_like of int, shape (N,)
            The samples' times, increasing (ns).
        us : array_like, shape (N,)
            The command each sample holds; a command starts at the first sample holding it.
        state : ServoState, optional
            From the previous piece of the same stream (default: the stream starts here).

        Returns
        -------
        x : numpy.ndarray, shape (N,)
        state : ServoState

        A stream cut into pieces gives the same output, to the bit, as in one piece.
        """
        t, u = _stream(times_ns, us)
        before = state or ServoState()
        if t.size == 0:
            return np.zeros(0), before
        changes, values = servo_changes(t, u, before.last_u)
        dead = self.dead_ns
        events_t = [int(s) for s, _ in before.pending] + (changes + dead).tolist()
        events_v = [float(v) for _, v in before.pending] + values.tolist()
        if before.anchor_ns is None:  # at rest at the first command until its event
            first_v = events_v[0]
            anchor_t = min(int(t[0]), events_t[0]) - 1
            anchor_x = anchor_v = first_v
        else:
            anchor_t, anchor_x, anchor_v = before.anchor_ns, before.anchor_x, before.anchor_v
        # the events up to the last sample: (S1) from one to the next, once per event
        last = int(t[-1])
        due = 0
        while due < len(events_t) and events_t[due] <= last:
            due += 1
        ev_t = np.empty(due + 1, dtype=np.int64)
        ev_v = np.empty(due + 1)
        ev_t[0], ev_v[0] = anchor_t, anchor_v
        ev_t[1:], ev_v[1:] = events_t[:due], events_v[:due]
        tau_ns = self.tau_ns
        ev_x = _event_outputs(events_t[:due], events_v[:due], anchor_t, anchor_x, anchor_v, tau_ns)
        after = ServoState(
            float(u[-1]),
            int(ev_t[-1]),
            float(ev_x[-1]),
            float(ev_v[-1]),
            tuple(zip(events_t[due:], events_v[due:], strict=True)),
        )
        return _sample_outputs(t, ev_t, ev_x, ev_v, tau_ns), after


def _stream(
    times_ns: ArrayLike, us: ArrayLike
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.float64]]:
    """Sample times and commands as arrays, checked 1-D of one length."""
    t = np.asarray(times_ns, dtype=np.int64)
    u = np.asarray(us, dtype=np.float64)
    if t.shape != u.shape or t.ndim != 1:
        raise GenBacklashError(
            f"times and commands must be 1-D of one length: {t.shape}, {u.shape}"
        )
    return t, u


class _Outputs:
    """Every candidate servo's output on one stream from its start: what
    ``model.output(times_ns, us)[0]`` returns, to the bit, with the lag's recursion (S1)
    run once per time constant instead of once per candidate.

    From the stream's start the outputs at the events do not depend on the dead time: the
    servo rests at the first command until the first event (so the first step of (S1) adds
    ``(v - v) exp(...) = 0``), and the dead time shifts every later event alike (the
    differences of integer stamps are exact). A dead time only moves the events against
    the samples and decides how many are due.
    """

    def __init__(self, times_ns: ArrayLike, us: ArrayLike) -> None:
        self._t, self._u = _stream(times_ns, us)
        changes, values = servo_changes(self._t, self._u)
        self._changes, self._values = changes, values
        self._paths: dict[float, FloatArray] = {}  # time constant (ns) -> output per event

    def __call__(self, model: ServoModel) -> FloatArray:
        t = self._t
        if t.size == 0:
            return model.output(t, self._u)[0]
        tau_ns = model.tau_ns
        path = self._paths.get(tau_ns)
        if path is None:  # the events of a dead time 0, anchored where output() anchors them
            first = float(self._values[0])
            events = self._changes.tolist()
            path = _event_outputs(
                events, self._values.tolist(), events[0] - 1, first, first, tau_ns
            )
            self._paths[tau_ns] = path
        events_t = self._changes + model.dead_ns
        late = np.flatnonzero(events_t > t[-1])  # the events up to the last sample are due
        due = int(late[0]) if late.size else events_t.size
        ev_t = np.empty(due + 1, dtype=np.int64)
        ev_v = np.empty(due + 1)
        ev_t[0], ev_v[0] = t[0] - 1, self._values[0]
        ev_t[1:], ev_v[1:] = events_t[:due], self._values[:due]
        return _sample_outputs(t, ev_t, path[: due + 1], ev_v, tau_ns)


def _event_outputs(
    events_t: Sequence[int],
    events_v: Sequence[float],
    anchor_t: int,
    anchor_x: float,
    anchor_v: float,
    tau_ns: float,
) -> FloatArray:
    """The servo's output at the anchor and at each event (S1, from one to the next).

    ``events_t`` (ns, Python ints: their differences are exact) and ``events_v``: the
    events and the targets they start; the anchor: the last event before them, the output
    there and the target in force from it. Returns ``len(events_t) + 1`` outputs.
    """
    ev_x = np.empty(len(events_t) + 1)
    ev_x[0] = anchor_x
    x_now, t_now, v_now = anchor_x, anchor_t, anchor_v
    for j, (s, v) in enumerate(zip(events_t, events_v, strict=True)):
        if tau_ns > 0.0:
            x_now = v_now + (x_now - v_now) * math.exp(-(s - t_now) / tau_ns)  # (S1)
        else:
            x_now = v_now
        t_now, v_now = s, v
        ev_x[j + 1] = x_now
    return ev_x


def _sample_outputs(
    t: npt.NDArray[np.int64],
    ev_t: npt.NDArray[np.int64],
    ev_x: FloatArray,
    ev_v: FloatArray,
    tau_ns: float,
) -> FloatArray:
    """The servo's output at each sample from the event at or before it (S1)."""
    where = np.searchsorted(ev_t, t, side="right") - 1
    v_at = ev_v[where]
    if tau_ns > 0.0:
        x = v_at + (ev_x[where] - v_at) * np.exp(-(t - ev_t[where]) / tau_ns)
    else:
        x = v_at.copy()
    return np.asarray(x, dtype=np.float64)


def servo_changes(
    times_ns: ArrayLike, us: ArrayLike, last_u: float | None = None
) -> tuple[np.ndarray, FloatArray]:
    """The command changes the samples show: the time of the first sample holding each new
    value, and the value (the stream's first sample counts as a change unless it holds
    ``last_u``, the command of the sample before it).

    >>> t, v = servo_changes([0, 10, 20, 30], [1.0, 1.0, 2.0, 2.0])
    >>> t.tolist(), v.tolist()
    ([0, 20], [1.0, 2.0])
    """
    t = np.asarray(times_ns, dtype=np.int64)
    u = np.asarray(us, dtype=np.float64)
    change = np.ones(u.size, dtype=bool)
    change[1:] = u[1:] != u[:-1]
    if u.size and last_u is not None:
        change[0] = bool(u[0] != last_u)
    return t[change], u[change]


@dataclass(frozen=True)
class ServoFit:
    """What :func:`estimate_servo` found.

    Attributes
    ----------
    model : ServoModel
        The chosen servo.
    misfit : float
        Its score: the free-run NRMSE of the backlash identified on its modelled input.
    none_misfit : float
        The same score without a servo (``ServoModel(0, 0)``).
    evaluated : int
        Candidates scored.
    """

    model: ServoModel
    misfit: float
    none_misfit: float
    evaluated: int

    def to_dict(self) -> dict[str, float | int]:
        """The servo and its scores, for JSON."""
        return {
            **self.model.to_dict(),
            "misfit": self.misfit,
            "misfit_without": self.none_misfit,
            "candidates": self.evaluated,
        }


def estimate_servo(
    times_ns: ArrayLike,
    us: ArrayLike,
    ys: ArrayLike,
    breaks: ArrayLike | None = None,
    *,
    degree: int = 1,
    dead_times: Sequence[float] = DEAD_TIMES,
    time_constants: Sequence[float] = TIME_CONSTANTS,
    rounds: int = _REFINE_ROUNDS,
) -> ServoFit:
    """The servo's dead time and lag estimated with the play.

    Each candidate ``(D, T)`` maps the held commands to the modelled servo output at each
    sample (:meth:`ServoModel.output`, S1); a backlash of ``degree`` is identified from that
    input and the readings (eqs. 22-29, the iteration without the output-error refinement)
    and scored by its free-run NRMSE on the same samples. The coarse grid
    ``dead_times x time_constants`` is searched first, then a compass search from the best:
    its eight neighbours at half the grid's spacing, moving while one scores better, the
    step halved when none does, ``rounds`` halvings (both values kept at 0 or above).
    Each candidate's input and score are those of ``ServoModel(D, T).output`` and
    ``identify_backlash(..., refine=False).fit.nrmse``, to the bit, at less cost (see the
    module notes).

    Parameters
    ----------
    times_ns, us, ys : array_like, shape (N,)
        Sample times (ns, increasing), the command each holds, the readings.
    breaks : array_like of bool, optional
        The sample rule's breaks (rows are never formed across one).
    degree : int
        Degree of the backlash scored (1, the ideal one, is enough to place the servo).

    Returns
    -------
    ServoFit

    Raises
    ------
    GenBacklashError
        When no candidate could be scored (too few samples, no excitation).
    """
    from .identify import backlash_misfit  # the identifier imports nothing of this

    outputs = _Outputs(times_ns, us)
    y = np.asarray(ys, dtype=np.float64)
    b: BoolArray | None = None if breaks is None else np.asarray(breaks, dtype=bool)
    scores: dict[tuple[float, float], float] = {}

    def score(dead: float, tau: float) -> float:
        key = (round(dead, 7), round(tau, 7))
        if key not in scores:
            x = outputs(ServoModel(key[0], key[1]))
            try:
                fit = backlash_misfit(x, y, degree, breaks=b)  # eqs. 22-29, free run
            except GenBacklashError:
                fit = math.inf
            scores[key] = fit if math.isfinite(fit) else math.inf
        return scores[key]

    best = min(((d, c) for d in dead_times for c in time_constants), key=lambda p: score(*p))
    if not math.isfinite(score(*best)):
        raise GenBacklashError(
            "the servo could not be estimated: no candidate's backlash could be identified "
            "from these samples (too few, or too little excitation)"
        )
    step_d = _spacing(dead_times, best[0]) / 2
    step_c = _spacing(time_constants, best[1]) / 2
    halvings = 0
    while halvings < rounds:
        # the eight neighbours at this step (the dead time and the lag trade off along a
        # diagonal valley, which steps along one axis at a time would crawl down)
        d0, c0 = best
        around = [
            (max(d0 + i * step_d, 0.0), max(c0 + j * step_c, 0.0))
            for i in (-1, 0, 1)
            for j in (-1, 0, 1)
            if i or j
        ]
        moved = min(around, key=lambda p: score(*p))
        if score(*moved) < score(*best):
            best = moved  # the same step again from there
        else:
            step_d, step_c, halvings = step_d / 2, step_c / 2, halvings + 1
    return ServoFit(ServoModel(*best), score(*best), score(0.0, 0.0), len(scores))


def _spacing(grid: Sequence[float], at: float) -> float:
    """The grid's spacing next to ``at`` (the larger of its two neighbours' distances)."""
    values = sorted(set(grid))
    if len(values) < 2:
        return max(abs(at), 1e-3)
    i = values.index(at) if at in values else int(np.argmin([abs(v - at) for v in values]))
    gaps = []
    if i > 0:
        gaps.append(values[i] - values[i - 1])
    if i + 1 < len(values):
        gaps.append(values[i + 1] - values[i])
    return max(gaps)
