"""The inverse-backlash step (the three cases of the module notes), its loop over a series,
and the stateful :class:`InverseBacklash`; the tests hold the two forms equal.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from genbacklash_core._typing import ArrayLike, FloatArray
from genbacklash_core.backlash import GeneralBacklash
from genbacklash_core.cascade import Cascade
from genbacklash_core.errors import GenBacklashError

from .branches import EPS, HOLD_ULPS, MAX, Plan, plan_for
from .options import DEFAULT_OPTIONS, CompensatorOptions, as_options
from .state import CompensatorState, plain_memory

# --------------------------------------------------------------------------- the step


_Memory = tuple[float, float, float, int, float, int]
"""A :class:`CompensatorState` as a plain tuple, in its field order (the loops' form)."""


def _memory_of(state: CompensatorState) -> _Memory:
    return (state.x, state.u, state.u_inverse, state.direction, state.offset, state.ramp)


def _step(
    plan: Plan,
    state: CompensatorState,
    x_d: float,
    options: CompensatorOptions,
    confidence: float,
) -> tuple[float, CompensatorState]:
    u, after = _advance(plan, _memory_of(state), x_d, options, confidence)
    return u, CompensatorState(*after)


def _advance(
    plan: Plan,
    memory: _Memory,
    x_d: float,
    options: CompensatorOptions,
    confidence: float,
) -> tuple[float, _Memory]:
    """One step of the compensator on the state as a tuple (:func:`_step` without building
    a :class:`CompensatorState`; the loops keep the tuple between samples)."""
    x, u_prev, v_prev, direction, offset, ramp = memory
    if not math.isfinite(x_d):  # no usable target: hold the previous command
        u = min(max(u_prev, options.u_min), options.u_max)
        return u, (plan.clamp(x, u), u, v_prev, direction, offset, ramp)
    up, down = plan.up, plan.down
    # Which case of eq. (8): push up (lower branch), push down (upper branch) or hold.
    scale = max(abs(x), abs(x_d), plan.left.magnitude(v_prev), plan.right.magnitude(v_prev))
    tol = HOLD_ULPS * EPS * min(scale, MAX)
    if x_d - x > tol:
        push = 1
        v = up.invert_fast(x_d, v_prev)  # lo(v) = x_d: R for increasing branches (eq. 12)
    elif x - x_d > tol:
        push = -1
        v = down.invert_fast(x_d, v_prev)  # hi(v) = x_d: L for increasing branches (eq. 11)
    else:  # hold inside the gap (eq. 8, middle case): keep v_prev if it keeps x
        push = 0
        left, right = plan.left.value(v_prev), plan.right.value(v_prev)
        if min(left, right) - x_d > tol:  # v_prev beyond z of the lifting branch
            v = up.invert_fast(x_d, v_prev)
        elif x_d - max(left, right) > tol:
            v = down.invert_fast(x_d, v_prev)
        else:
            v = v_prev

    # Gap-crossing smoothing: a new push direction starts a linear ramp of the jump.
    if push != 0:
        if push != direction and options.smoothing > 0:
            offset = v - (v_prev - offset)  # the whole jump from the last smoothed command
            ramp = options.smoothing
            if not math.isfinite(offset):  # a jump beyond the float range: taken at once
                offset, ramp = 0.0, 0
        direction = push
    if ramp > 0:
        offset -= offset / ramp  # deliver 1/ramp of what is left; exactly 0 at the last
        ramp -= 1
    command = v - offset

    # Confidence gating: fade to pass-through u = x_d.
    w = options.weight(confidence)
    if w >= 1.0:
        u = command
    elif w <= 0.0:
        u = x_d
    else:
        u = x_d + w * (command - x_d)
    if not math.isfinite(u):
        u = u_prev
    # Rate limit, then output limits (the limits win if the previous command was outside).
    rate = options.max_rate
    if u - u_prev > rate:
        u = u_prev + rate
        while u - u_prev > rate:  # undo a rounding up of u_prev + rate
            u = math.nextafter(u, u_prev)
    elif u_prev - u > rate:
        u = u_prev - rate
        while u_prev - u > rate:
            u = math.nextafter(u, u_prev)
    if u < options.u_min:
        u = options.u_min
    elif u > options.u_max:
        u = options.u_max
    # Advance the modelled output with the command actually sent (eq. 20).
    return u, (plan.clamp(x, u), u, v, direction, offset, ramp)


def _same_float(a: float, b: float) -> bool:
    """``a`` and ``b`` are the same number, a zero's sign included (``0.0 == -0.0`` alone
    would let a step's output take the other zero's sign)."""
    return a == b and (a != 0.0 or math.copysign(1.0, a) == math.copysign(1.0, b))


def _same_memory(a: _Memory, b: _Memory) -> bool:
    """Two states as tuples are the same bit for bit (zeros' signs included)."""
    return (
        a == b
        and _same_float(a[0], b[0])
        and _same_float(a[1], b[1])
        and _same_float(a[2], b[2])
        and _same_float(a[4], b[4])
    )


def _as_float(name: str, value: object) -> float:
    try:
        return float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError) as err:
        raise GenBacklashError(f"{name} must be a number, got {value!r}") from err


def compensate_step(
    model: GeneralBacklash | Cascade,
    state: CompensatorState,
    x_d: float,
    options: CompensatorOptions | None = None,
    confidence: float = 1.0,
) -> tuple[float, CompensatorState]:
    """One sample of the inverse-backlash compensator (pure function).

    Parameters
    ----------
    model : GeneralBacklash or Cascade
        The model; of a cascade only the backlash is inverted.
    state : CompensatorState
        State after the previous sample (:meth:`CompensatorState.initial` to start).
    x_d : float
        Desired backlash output. A non-finite value holds the previous command.
    options : CompensatorOptions, optional
    confidence : float
        Trust in the model, gated by ``options.gate_low``/``gate_high``.

    Returns
    -------
    u : float
        The command to send; finite, within the limits and the rate limit.
    state : CompensatorState
        The next state; its ``x`` is the modelled output under ``u``.

    Examples
    --------
    >>> bl = GeneralBacklash.ideal(1.0, 0.5, 0.5)
    >>> state = CompensatorState.initial(bl)
    >>> u, state = compensate_step(bl, state, 1.0)  # push up: R(u) = u - 0.5 = 1
    >>> u, state.x
    (1.5, 1.0)
    >>> u, state = compensate_step(bl, state, 0.9)  # reversal: jump to L(u) = u + 0.5 = 0.9
    >>> round(u, 12)
    0.4
    """
    opts = DEFAULT_OPTIONS if options is None else as_options(options)
    if not isinstance(state, CompensatorState):
        raise GenBacklashError(f"state must be a CompensatorState, got {state!r}")
    return _step(
        plan_for(model, opts),
        state,
        _as_float("x_d", x_d),
        opts,
        _as_float("confidence", confidence),
    )


def _series(x_d: ArrayLike, confidence: ArrayLike) -> tuple[list[float], list[float]]:
    try:
        target = np.asarray(x_d, dtype=np.float64)
        trust = np.asarray(confidence, dtype=np.float64)
    except (TypeError, ValueError) as err:
        raise GenBacklashError("x_d and confidence must be numeric arrays") from err
    if target.ndim != 1:
        raise GenBacklashError(f"x_d must be one-dimensional, got shape {target.shape}")
    try:
        trust = np.broadcast_to(trust, target.shape)
    except ValueError as err:
        raise GenBacklashError(
            f"confidence of shape {trust.shape} does not fit x_d of shape {target.shape}"
        ) from err
    return target.tolist(), trust.tolist()


def compensate(
    model: GeneralBacklash | Cascade,
    x_d: ArrayLike,
    options: CompensatorOptions | None = None,
    confidence: ArrayLike = 1.0,
    state: CompensatorState | None = None,
) -> FloatArray:
    """Compensated commands for a whole desired path (loops :func:`compensate_step`).

    Parameters
    ----------
    model : GeneralBacklash or Cascade
    x_d : array_like, shape (N,)
        Desired backlash output; non-finite samples hold the previous command.
    options : CompensatorOptions, optional
    confidence : float or array_like, shape (N,)
    state : CompensatorState, optional
        Start state; default :meth:`CompensatorState.initial` (load at rest at ``x = 0``,
        as :func:`~genbacklash_core.simulate_backlash` starts by default).

    Returns
    -------
    ndarray, shape (N,)
        The commands ``u``; the modelled backlash driven by them follows ``x_d``.

    Examples
    --------
    >>> from genbacklash_core import simulate_backlash
    >>> bl = GeneralBacklash((0.5, -0.3, 0.3), 0.7, (0.6, 0.4, 0.2), 0.8)
    >>> x_d = [0.2, 0.6, 0.6, 0.1, -0.4, 0.0]
    >>> u = compensate(bl, x_d)
    >>> np.allclose(simulate_backlash(bl, u), x_d, rtol=0, atol=1e-12)
    True
    """
    opts = DEFAULT_OPTIONS if options is None else as_options(options)
    plan = plan_for(model, opts)
    current = CompensatorState.initial(model, options=opts) if state is None else state
    if not isinstance(current, CompensatorState):
        raise GenBacklashError(f"state must be a CompensatorState, got {current!r}")
    targets, trusts = _series(x_d, confidence)
    out = np.empty(len(targets))
    memory = _memory_of(current)
    for t, (target, trust) in enumerate(zip(targets, trusts, strict=True)):
        out[t], memory = _advance(plan, memory, target, opts, trust)
    return out


# --------------------------------------------------------------------------- stateful form


class InverseBacklash:
    """Stateful inverse-backlash compensator: a feedforward block for a control loop.

    Parameters
    ----------
    model : GeneralBacklash or Cascade
        Of a cascade only the backlash is inverted.
    options : CompensatorOptions, optional
    x0 : float
        Initial load position (modelled backlash output).
    u0 : float, optional
        Initial command; default the middle of the hold interval of ``x0``.

    Examples
    --------
    >>> comp = InverseBacklash(GeneralBacklash.ideal(1.0, 0.5, 0.5))
    >>> [comp.step(x) for x in (0.5, 1.0, 1.0)]
    [1.0, 1.5, 1.5]
    >>> round(comp.step(0.8), 12)  # reversal: across the gap of width 1
    0.3
    >>> comp.set_model(GeneralBacklash.ideal(1.0, 0.4, 0.4))  # an online estimate arrives
    >>> round(comp.step(0.8), 12), comp.state.x
    (0.4, 0.8)
    """

    def __init__(
        self,
        model: GeneralBacklash | Cascade,
        options: CompensatorOptions | None = None,
        x0: float = 0.0,
        u0: float | None = None,
    ) -> None:
        self._options = DEFAULT_OPTIONS if options is None else as_options(options)
        self._plan = plan_for(model, self._options)
        self._model = model
        # the state as a tuple (what the steps take and give), and as a CompensatorState
        # once asked for (None: not built yet; a step on a node's command does not build it)
        state = CompensatorState.initial(model, x0, u0, self._options)
        self._memory: _Memory = _memory_of(state)
        self._snapshot: CompensatorState | None = state
        # a settled step of the last run: (its state, target, confidence, command)
        self._repeat: tuple[_Memory, float, float, float] | None = None
        # the same for the last step() (bit for bit: its own, the run's compares by value)
        self._held: tuple[_Memory, float, float, float] | None = None

    @property
    def model(self) -> GeneralBacklash | Cascade:
        """The model in use."""
        return self._model

    @property
    def options(self) -> CompensatorOptions:
        """The options in use."""
        return self._options

    @property
    def state(self) -> CompensatorState:
        """The current state (a frozen snapshot; assign a state to continue from it)."""
        state = self._snapshot
        if state is None:
            self._snapshot = state = CompensatorState(*self._memory)
        return state

    @state.setter
    def state(self, value: CompensatorState) -> None:
        if not isinstance(value, CompensatorState):
            raise GenBacklashError(f"state must be a CompensatorState, got {value!r}")
        if value is not self._snapshot:
            self._snapshot, self._memory = value, _memory_of(value)

    def set_model(self, model: GeneralBacklash | Cascade) -> None:
        """Replace the model while running; the state carries over.

        Raises (and keeps the old model) when the new one cannot be inverted on the range.
        """
        self._plan = plan_for(model, self._options)
        self._model = model
        self._repeat = self._held = None  # a step of the old plan

    def reset(self, x0: float = 0.0, u0: float | None = None) -> None:
        """Restart at rest: load at ``x0``, command ``u0`` (as :meth:`CompensatorState.initial`)."""
        state = CompensatorState.initial(self._model, x0, u0, self._options)
        self._snapshot, self._memory = state, _memory_of(state)

    def step(self, x_d: float, confidence: float = 1.0) -> float:
        """The command for one desired output sample; see :func:`compensate_step`.

        A step is a function of (state, target, confidence): a held target on a state the
        last step left unchanged gives the same command and state again, so it is not
        recomputed (as :meth:`steps` does; a node's held commands).
        """
        target = _as_float("x_d", x_d)
        trust = _as_float("confidence", confidence)
        memory = self._memory
        held = self._held
        if (
            held is not None
            and held[0] is memory
            and _same_float(target, held[1])
            and _same_float(trust, held[2])
        ):
            return held[3]
        u, after = _advance(self._plan, memory, target, self._options, trust)
        if plain_memory(after):  # a valid state as it is: built only when asked for
            self._snapshot = None
        else:  # what CompensatorState makes of it (converted, or why not raised)
            state = CompensatorState(*after)
            self._snapshot, after = state, _memory_of(state)
        self._memory = after
        self._held = (after, target, trust, u) if _same_memory(after, memory) else None
        return u

    def run(self, x_d: ArrayLike, confidence: ArrayLike = 1.0) -> FloatArray:
        """Commands for a block of samples, continuing from (and advancing) the state."""
        targets, trusts = _series(x_d, confidence)
        return np.array(self._run(targets, trusts), dtype=np.float64)

    def steps(self, x_d: Sequence[float], confidence: float = 1.0) -> list[float]:
        """:meth:`step` for each of ``x_d`` in turn, at one ``confidence``: the commands.

        The form for a caller with Python floats at hand (the node's batch path); the same
        commands and state as the calls one by one.

        >>> comp = InverseBacklash(GeneralBacklash.ideal(1.0, 0.5, 0.5))
        >>> comp.steps([0.5, 1.0, 1.0])
        [1.0, 1.5, 1.5]
        """
        targets = [_as_float("x_d", x) for x in x_d]
        trust = _as_float("confidence", confidence)
        return self._run(targets, [trust] * len(targets))

    def _run(self, targets: list[float], trusts: list[float]) -> list[float]:
        memory = start = self._memory
        plan, options = self._plan, self._options
        out = []
        # A step is a function of (state, target, confidence): a held command on a state the
        # step left unchanged gives the same command and state again (a dwell's repeats).
        # ``settled``: (target, confidence, command) of such a step, from the last run too
        # while its state is still the current one and the plan the same.
        repeat = self._repeat
        settled = repeat[1:] if repeat is not None and repeat[0] is start else None
        for target, trust in zip(targets, trusts, strict=True):
            if settled is not None and target == settled[0] and trust == settled[1]:
                out.append(settled[2])
                continue
            u, after = _advance(plan, memory, target, options, trust)
            settled = (target, trust, u) if after == memory else None
            memory = after
            out.append(u)
        if plain_memory(memory):  # a valid state as it is: built only when asked for (as step)
            self._snapshot = None
            memory = (*memory,)  # a new state object, as a snapshot's would be
        else:  # what CompensatorState makes of it (converted, or why not raised)
            state = CompensatorState(*memory)
            self._snapshot, memory = state, _memory_of(state)
        self._memory = memory
        self._repeat = None if settled is None else (memory, *settled)
        return out
