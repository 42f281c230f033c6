"""The message-level node logic shared by every transport and by bag replay.

:class:`BacklashPipeline` takes command and encoder messages (:mod:`genbacklash_ros.node.messages`)
with the time they were received, and returns what to publish as :class:`Output` events --
the compensated command, the estimate, the diagnostics -- so a transport (rclpy, DDS) or the
replay only converts and publishes. It imports no transport and reads no clock: every decision
is taken on the data's own time, so a replay of a bag is deterministic and is the node.

Alignment (integer nanoseconds throughout)
-----------------------------------------
* **Time of a message.** With ``stamp_source = "header"`` a message's header stamp, and its
  receive time when it has no header (Float64, Float64MultiArray) or a zero stamp; with
  ``"receive"`` always the receive time. The *data clock* is the latest accepted time.
* **Order.** Per stream, a time must exceed the previous accepted one: an equal time is a
  duplicate, an earlier one out of order; both are dropped and counted (as are messages the
  adapters reject and non-finite values). Nothing raises out of the pipeline.
* **Zero-order hold.** The command holds from its time until the next command: the input of
  a sample at time ``t`` is the latest command with time ``<= t``.
* **Sample times.** One sample per encoder message, at its time (``sample_period = 0``), or
  on the fixed grid ``t = k * sample_period`` with the encoder held as well.
* **When a sample is final.** A sample at ``t`` is fed to the identifier once its command is
  known: a command with time ``>= t`` has arrived (so no earlier one can follow, given the
  order rule), or the encoder stream is ``command_wait_ns`` (default 0.1 s) past ``t`` (the
  command is then taken as held). Samples before the first command are skipped and counted.
* **Batches.** Final samples are fed with ``update_many`` on an encoder message when
  ``batch`` encoder messages are pending, when the data clock is ``batch_ns`` past the last
  feed, or an estimate is due; so the estimate the compensator uses is at most about one
  batch old. A command message never feeds nor checkpoints: its compensated command costs
  one compensator step (tens of microseconds), whatever the identifier costs.
* **Identifier input.** The raw command, or with ``compensation_in_loop`` the compensated
  command that was sent (what the drivetrain then really gets).
* **Consecutive samples.** A regression row pairs only samples that are consecutive on the
  encoder's clock (:mod:`genbacklash_core.samples`; applied by
  :mod:`genbacklash_ros.node.sample_rule`, the rule batch ``identify`` and ``diagnose`` on bags
  use too). Each feed passes ``update_many(u, y, breaks=...)``: sample ``k`` breaks when the
  stamps of the encoder readings it and the sample before it hold (for the first sample of
  a feed: the last sample fed before) differ by other than one nominal period, rounded --
  a lost reading, a gap, a clock that jumped -- or when a sample or reading was taken out in
  between: a rejected encoder message (invalid, not finite), a stuck encoder's readings,
  samples before the first command, a spike or a sample held back after a gap
  (:meth:`~genbacklash_ros.node.health.StreamHealth.screen`), a batch the identifier refused, a
  re-anchor after a clock jump back. Duplicate and out-of-order messages are not readings
  taken out (their stamps are not new). The nominal period is the median of the last
  :data:`~genbacklash_ros.node.sample_rule.PERIOD_WINDOW` differences of accepted encoder stamps
  (jitter of up to half a period on a difference keeps neighbours neighbours); on the fixed
  grid it is ``sample_period`` and the stamps are those of the readings the grid points
  hold, so a grid sample breaks when it holds the same reading as the one before (the
  reading it should hold was lost or is late) or a reading more than a grid period, rounded,
  after it. An encoder slower than the grid thus breaks every chain: set ``sample_period``
  to the encoder's period or a multiple of it.

Outputs
-------
* one ``compensated_command`` per accepted command message, of the command's type and time,
  computed by :class:`~genbacklash_core.InverseBacklash` with the current estimate and its
  confidence (the raw command when ``compensate`` is false; limited but uncorrected while
  there is no model);
* ``estimate`` every ``1 / publish_rate`` of data time while an estimate exists;
* ``diagnostics`` every second of data time: OK while converging or converged, WARN while
  warming up, without excitation or when messages were dropped since the last report (the
  reasons are in the message), ERROR when diverged.

The estimate is checkpointed every ``checkpoint_period`` of data time when
``checkpoint_file`` is set, and warm-started from it at construction
(:func:`~genbacklash_ros.node.checkpoint.warm_start`).

Faults
------
Nothing raises and no non-finite number is published, whatever arrives. On top of that,
signs that the measurements (or their times) cannot be trusted -- rejected messages, a
silent, lossy, spiking or stuck encoder, a clock that jumps, a saturated command -- start a
*fault*: while one is active the compensated command is the command itself and
``/diagnostics`` says why. :class:`~genbacklash_ros.node.health.StreamHealth` detects them; the
rules and their thresholds (re-exported here) are in :mod:`genbacklash_ros.node.health`.

Examples
--------
>>> from genbacklash_ros.node.messages import Float64, Header, JointState, Time
>>> from genbacklash_ros.node.parameters import NodeParameters
>>> pipe = BacklashPipeline(NodeParameters(command_type="float64"))
>>> pipe.on_command(Float64(0.5), receive_ns=1_000_000)[0].message
Float64(data=0.5)
>>> encoder = JointState(Header(Time.from_ns(2_000_000)), ("j",), (0.1,))
>>> pipe.on_encoder(encoder, receive_ns=2_100_000)
[]
>>> pipe.on_encoder(JointState(name=("j",), position=(float("nan"),)), receive_ns=3_000_000)
[]
>>> pipe.stats.dropped["encoder_invalid"]
1
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Literal, TypeAlias

import numpy as np

from genbacklash_core import (
    CompensatorOptions,
    Estimate,
    EstimatorState,
    GenBacklashError,
    InverseBacklash,
    OnlineIdentifier,
)
from genbacklash_ros.node.checkpoint import Checkpoint, CheckpointError, save_checkpoint, warm_start

# the fault thresholds live with the rules in health.py; importable from here as before
from genbacklash_ros.node.health import _SCALE_SMOOTHING as _SCALE_SMOOTHING
from genbacklash_ros.node.health import FAULT_HOLD_NS as FAULT_HOLD_NS
from genbacklash_ros.node.health import LOSS_WINDOW_NS as LOSS_WINDOW_NS
from genbacklash_ros.node.health import LOSS_WINDOW_READINGS as LOSS_WINDOW_READINGS
from genbacklash_ros.node.health import MAX_LOSS as MAX_LOSS
from genbacklash_ros.node.health import REANCHOR_BACK_NS as REANCHOR_BACK_NS
from genbacklash_ros.node.health import REANCHOR_COUNT as REANCHOR_COUNT
from genbacklash_ros.node.health import RESYNC_NS as RESYNC_NS
from genbacklash_ros.node.health import SATURATION_NS as SATURATION_NS
from genbacklash_ros.node.health import SILENCE_MIN_NS as SILENCE_MIN_NS
from genbacklash_ros.node.health import SILENCE_PERIODS as SILENCE_PERIODS
from genbacklash_ros.node.health import SILENCE_UNKNOWN_NS as SILENCE_UNKNOWN_NS
from genbacklash_ros.node.health import SPIKE_MAX_SHARE as SPIKE_MAX_SHARE
from genbacklash_ros.node.health import SPIKE_SIGMAS as SPIKE_SIGMAS
from genbacklash_ros.node.health import STILL_HOLD_NS as STILL_HOLD_NS
from genbacklash_ros.node.health import STUCK_NS as STUCK_NS
from genbacklash_ros.node.health import STUCK_SIGMAS as STUCK_SIGMAS
from genbacklash_ros.node.health import StreamHealth
from genbacklash_ros.node.messages import (
    CommandMessage,
    DiagnosticArray,
    DiagnosticStatus,
    Float64,
    Float64MultiArray,
    JointState,
    MessageError,
    compensated_command,
    diagnostic_array,
    estimate_message,
    level_of,
    read_command,
    read_encoder,
)
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.sample_rule import EncoderPeriod, keep_breaks, link_breaks

__all__ = [
    "COMMAND_WAIT_NS",
    "DIAGNOSTICS_PERIOD_NS",
    "FAULT_HOLD_NS",
    "BacklashPipeline",
    "CheckpointWriter",
    "Output",
    "PipelineStats",
    "TopicKey",
]

TopicKey: TypeAlias = Literal["compensated_command", "estimate", "diagnostics"]
CheckpointWriter: TypeAlias = Callable[[Path, Checkpoint], object]

COMMAND_WAIT_NS = 100_000_000  # encoder time after which a sample's command counts as held
DIAGNOSTICS_PERIOD_NS = 1_000_000_000  # /diagnostics at 1 Hz of data time
BATCH_SAMPLES = 64  # encoder messages per identifier feed
BATCH_NS = 100_000_000  # data time between identifier feeds at most
_MAX_COMMANDS = 4096  # command history kept while no encoder data consume it

_DROP_KEYS = (
    "command_invalid",
    "command_duplicate",
    "command_out_of_order",
    "encoder_invalid",
    "encoder_duplicate",
    "encoder_out_of_order",
    "identifier_error",
    "before_first_command",
    "encoder_spike",
    "encoder_stuck",
    "encoder_after_gap",
)
# expected at start, or reported as a fault of their own: counted, no WARN of their own
_QUIET_DROPS = frozenset({"before_first_command", "encoder_stuck", "encoder_after_gap"})
_ENCODER_REJECTS = frozenset({"encoder_invalid", "encoder_duplicate", "encoder_out_of_order"})
_COMMAND_CLASSES: dict[str, type] = {
    "float64": Float64,
    "float64_multi_array": Float64MultiArray,
    "joint_state": JointState,
}


@dataclass(frozen=True, slots=True)
class Output:
    """One message to publish.

    Attributes
    ----------
    topic : {"compensated_command", "estimate", "diagnostics"}
        Which publisher (GUIDE §4: ``compensated_command``, ``~/estimate``, ``/diagnostics``).
    message : Float64, Float64MultiArray, JointState or DiagnosticArray
    stamp_ns : int
        Data time of the message (a compensated command: its command's time), e.g. the log
        time when writing a bag.
    estimate : Estimate or None
        The estimate behind an ``estimate`` or ``diagnostics`` output (with its covariance,
        for reports); None for commands.
    """

    topic: TopicKey
    message: CommandMessage | Float64MultiArray | DiagnosticArray
    stamp_ns: int
    estimate: Estimate | None = None


@dataclass(frozen=True)
class PipelineStats:
    """Counters since construction (a snapshot).

    ``dropped`` maps each reason key (``command_invalid``, ``command_duplicate``,
    ``command_out_of_order``, the same for ``encoder_``, ``identifier_error``,
    ``before_first_command``, ``encoder_spike``, ``encoder_stuck``, ``encoder_after_gap``)
    to a count; ``last_problem`` is the latest reason text.
    """

    commands: int
    encoder_messages: int
    samples: int
    compensated: int
    checkpoints: int
    checkpoint_errors: int
    dropped: MappingProxyType[str, int]
    last_problem: str


def _next_multiple(now: int, period: int) -> int:
    """The first multiple of ``period`` after ``now``."""
    return (now // period + 1) * period


def _order_text(stream: str, stamp: int, last: int) -> str:
    """Why a message of ``stream`` at ``stamp`` is dropped after one at ``last``."""
    text = f"{stream} time {stamp} ns is not after the previous {last} ns"
    return text if stamp == last else f"{text} ({(last - stamp) / 1e9:.3f} s back)"


class BacklashPipeline:
    """Command and encoder messages in, compensated command, estimate and diagnostics out.

    Parameters
    ----------
    params : NodeParameters
    checkpoint_writer : callable, optional
        ``writer(path, checkpoint)`` saving a :class:`~genbacklash_ros.node.checkpoint.Checkpoint`;
        default :func:`~genbacklash_ros.node.checkpoint.save_checkpoint` (synchronous, with an
        fsync: a live transport may pass one that writes on another thread).
    command_wait_ns : int
        Encoder time after which a sample's command is taken as held (see the module notes).
    batch : int
        Encoder messages per identifier feed at most.
    batch_ns : int
        Data time between identifier feeds at most.

    Notes
    -----
    Not thread-safe: a transport calls it from one thread (or under one lock). Read the
    module notes for the alignment rules.
    """

    def __init__(
        self,
        params: NodeParameters,
        *,
        checkpoint_writer: CheckpointWriter | None = None,
        command_wait_ns: int = COMMAND_WAIT_NS,
        batch: int = BATCH_SAMPLES,
        batch_ns: int = BATCH_NS,
    ) -> None:
        if not isinstance(params, NodeParameters):
            raise GenBacklashError(f"params must be NodeParameters, got {params!r}")
        for name, value, low in (
            ("command_wait_ns", command_wait_ns, 0),
            ("batch", batch, 1),
            ("batch_ns", batch_ns, 1),
        ):
            if isinstance(value, bool) or not isinstance(value, int) or value < low:
                raise GenBacklashError(f"{name} must be a whole number >= {low}, got {value!r}")
        self._writer: CheckpointWriter = (
            checkpoint_writer if checkpoint_writer is not None else save_checkpoint
        )
        self._wait = command_wait_ns
        self._batch = batch
        self._batch_ns = batch_ns
        # counters
        self._dropped = dict.fromkeys(_DROP_KEYS, 0)
        self._period_drops: dict[str, int] = {}
        self._period_reasons: dict[str, str] = {}
        self._period_problems: list[str] = []
        self._last_problem = ""
        self._commands = 0
        self._encoders = 0
        self._samples = 0
        self._compensated = 0
        self._checkpoints = 0
        self._checkpoint_errors = 0
        self._last_checkpoint_ns: int | None = None
        self._params = params
        self._health = StreamHealth(
            estimate=lambda: self.estimate,
            drop=self._drop,
            note=self._note,
            discard=self._discard_after,
        )
        self._configure(params)
        self._start(params)

    # ------------------------------------------------------------------ configuration

    def _configure(self, params: NodeParameters) -> None:
        """Settings that change without a restart."""
        self._params = params
        self._options: CompensatorOptions = params.compensator_options()
        self._publish_ns = params.publish_period_ns
        self._checkpoint_ns = params.checkpoint_period_ns
        self._checkpoint_path = Path(params.checkpoint_file) if params.checkpoint_file else None
        self._index = params.command_index
        self._joint = params.joint
        self._command_kind = params.command_type
        self._command_class = _COMMAND_CLASSES[params.command_type]
        self._encoder_kind = params.encoder_type

    def _start(self, params: NodeParameters) -> None:
        """(Re)start identification and alignment: warm start, empty buffers."""
        start = warm_start(params)
        self._identifier: OnlineIdentifier = start.identifier
        self._prior = start.prior
        self._warm_start_note = start.note
        if start.problem:
            self._problem(start.note)
        self._use_header = params.stamp_source == "header"
        self._grid_ns = params.sample_period_ns
        self._in_loop = params.compensation_in_loop
        # streams: accepted times and values (commands: what the identifier takes)
        self._cmd_t: list[int] = []
        self._cmd_u: list[float] = []
        self._enc_t: list[int] = []
        self._enc_y: list[float] = []
        # the sample rule (see the module notes): pending readings that follow one taken out,
        # whether the next accepted reading does, the encoder's period, the stamp of the
        # reading the identifier's last sample holds (None: the next sample breaks)
        self._enc_mark: list[bool] = []
        self._mark_next = False
        self._period = EncoderPeriod()
        self._fed_last_t: int | None = None
        self._last_cmd_ns: int | None = None
        self._last_enc_ns: int | None = None
        self._next_grid_k: int | None = None
        self._last_y: float | None = None
        self._last_sent: float | None = None
        # compensator: created when the first model is available
        self._comp: InverseBacklash | None = None
        self._comp_estimate: Estimate | None = None
        # the data clock and the periodic schedule (set by the first message)
        self._now: int | None = None
        self._next_estimate = 0
        self._next_diagnostics = 0
        self._next_checkpoint = 0
        self._next_feed_ns = 0
        self._feed_at_count = self._batch
        self._next_due = 0

    def set_params(self, params: NodeParameters) -> None:
        """Apply new parameters (validated already, e.g. by :meth:`NodeParameters.replace`).

        Parameters marked ``restarts`` in the specs restart identification and alignment (a
        warm start from the checkpoint file when it fits); the others apply at once, the
        compensator keeping its state.
        """
        if not isinstance(params, NodeParameters):
            raise GenBacklashError(f"params must be NodeParameters, got {params!r}")
        old = self._params
        self._configure(params)
        if old.restart_needed(params):
            self._start(params)
            self._health.reset()
            return
        comp = self._comp
        if comp is not None and old.compensator_options() != params.compensator_options():
            state = comp.state
            u0 = min(max(state.u, self._options.u_min), self._options.u_max)
            try:
                self._comp = InverseBacklash(comp.model, self._options, state.x, u0)
            except GenBacklashError as err:
                self._problem(f"compensator restarted: {err}")
                self._comp, self._comp_estimate = None, None
        if not params.compensate:  # re-initialised from the latest measurement when re-enabled
            self._comp, self._comp_estimate = None, None
        if self._now is not None:
            self._schedule(self._now)

    # ------------------------------------------------------------------ properties

    @property
    def params(self) -> NodeParameters:
        """The parameters in use."""
        return self._params

    @property
    def warm_start_note(self) -> str:
        """What the (last) start made of the checkpoint file ("" when none was used)."""
        return self._warm_start_note

    @property
    def identifier(self) -> OnlineIdentifier:
        """The online identifier (replaced on a restart)."""
        return self._identifier

    @property
    def estimate(self) -> Estimate:
        """The estimate in use: the identifier's, or the checkpoint's until the identifier's
        own has converged or is at least as confident."""
        est = self._identifier.estimate
        prior = self._prior
        if prior is None:
            return est
        if est.available and (
            est.state is EstimatorState.CONVERGED or est.confidence >= prior.confidence
        ):
            self._prior = None  # the identifier's estimate from now on
            return est
        return prior

    @property
    def using_checkpoint(self) -> bool:
        """True while the estimate rests on the checkpoint: the identifier continues from it
        and still leans on it (``from_seed``), or its estimate stands in for the identifier's."""
        return self.estimate is self._prior or self._identifier.from_seed

    @property
    def stats(self) -> PipelineStats:
        """Counters since construction."""
        return PipelineStats(
            self._commands,
            self._encoders,
            self._samples,
            self._compensated,
            self._checkpoints,
            self._checkpoint_errors,
            MappingProxyType(dict(self._dropped)),
            self._last_problem,
        )

    # ------------------------------------------------------------------ inputs

    def on_command(self, msg: CommandMessage, receive_ns: int) -> list[Output]:
        """A command message received at ``receive_ns``: the compensated command and any
        periodic outputs now due."""
        try:
            if not isinstance(msg, self._command_class):
                raise MessageError(
                    f"expected a {self._command_class.__name__}, got {type(msg).__name__}"
                )
            kind, index, joint = self._command_kind, self._index, self._joint
            header_ns, value = read_command(msg, kind, index=index, joint=joint)
        except MessageError as err:
            self._drop("command_invalid", f"command: {err}")
            return []
        accepted = self.on_command_value(header_ns, value, receive_ns)
        if accepted is None:
            return []
        stamp, sent, outputs = accepted
        out_msg = compensated_command(msg, sent, kind, index=index, joint=joint)
        outputs.insert(0, Output("compensated_command", out_msg, stamp))
        return outputs

    def on_command_value(
        self, header_ns: int | None, value: float, receive_ns: int
    ) -> tuple[int, float, list[Output]] | None:
        """A command already read from its message (header stamp, 0 when none): ``(time,
        compensated value, periodic outputs now due)``, or None when it is dropped.
        ``header_ns`` is None (or 0) for a message without a header.

        :meth:`on_command` is this plus the adapters; a transport that decodes messages
        itself (bag replay reads the value straight from the CDR bytes) calls it directly
        and writes the compensated value into its own copy of the message.
        """
        try:
            if not math.isfinite(value):
                raise MessageError(f"value {value} is not finite")
            stamp = header_ns if self._use_header and header_ns else int(receive_ns)
            last = self._last_cmd_ns
            if last is not None and stamp <= last:
                back = self._health.jumped_back("command", stamp, last)
                if back is None:
                    key = "command_duplicate" if stamp == last else "command_out_of_order"
                    self._drop(key, _order_text("command", stamp, last))
                    return None
                self._reanchor("command", stamp, last, back)
            self._health.check_command(stamp, value, int(receive_ns), self._options)
            sent = self._compensate(value, stamp)
        except MessageError as err:
            self._drop("command_invalid", f"command: {err}")
            return None
        self._last_cmd_ns = stamp
        self._last_sent = sent
        self._cmd_t.append(stamp)
        self._cmd_u.append(sent if self._in_loop else value)
        if len(self._cmd_t) > _MAX_COMMANDS:
            self._trim_commands()
        self._commands += 1
        self._compensated += 1
        outputs: list[Output] = []
        self._advance(stamp, outputs, heavy=False)
        return stamp, sent, outputs

    def on_encoder(self, msg: object, receive_ns: int) -> list[Output]:
        """An encoder message received at ``receive_ns``: any periodic outputs now due."""
        try:
            header_ns, value = read_encoder(msg, self._encoder_kind, joint=self._joint)
        except MessageError as err:
            self._drop("encoder_invalid", f"encoder: {err}")
            return []
        return self.on_encoder_value(header_ns, value, receive_ns)

    def on_encoder_value(
        self, header_ns: int | None, value: float, receive_ns: int
    ) -> list[Output]:
        """An encoder reading already read from its message (header stamp, 0 when none):
        any periodic outputs now due (:meth:`on_encoder` is this plus the adapters)."""
        if not math.isfinite(value):
            self._drop("encoder_invalid", f"encoder: value {value} is not finite")
            return []
        stamp = header_ns if self._use_header and header_ns else int(receive_ns)
        last = self._last_enc_ns
        if last is not None and stamp <= last:
            back = self._health.jumped_back("encoder", stamp, last)
            if back is None:
                key = "encoder_duplicate" if stamp == last else "encoder_out_of_order"
                self._drop(key, _order_text("encoder", stamp, last))
                return []
            self._reanchor("encoder", stamp, last, back)
            last = None  # re-anchored: this reading starts the new time line
        stuck = self._health.check_reading(
            stamp, last, value, self._last_y, int(receive_ns), self._cmd_t, self._cmd_u
        )
        if last is not None:
            self._period.add(stamp - last)
        self._last_enc_ns = stamp
        self._last_y = value
        if stuck:
            self._mark_next = True
        else:
            self._enc_t.append(stamp)
            self._enc_y.append(value)
            self._enc_mark.append(self._mark_next)
            self._mark_next = False
        self._encoders += 1
        outputs: list[Output] = []
        if len(self._enc_t) >= self._feed_at_count:
            self._feed()
        self._advance(stamp, outputs, heavy=True)
        return outputs

    def reject(self, stream: Literal["command", "encoder"], reason: str) -> None:
        """A message of ``stream`` its transport could not read (e.g. bytes that do not
        decode): counted and reported like one the adapters reject."""
        self._drop(f"{stream}_invalid", f"{stream}: {reason}")

    def finish(self, *, refit: bool = True) -> list[Output]:
        """End of the data (a replay's last message, a node shutting down).

        Feeds every pending sample (their commands taken as held), refits the windowed
        identifier on its window when ``refit``, and returns the final estimate and
        diagnostics; checkpoints when a file is set.
        """
        outputs: list[Output] = []
        self._feed(final=True)
        refit_now = getattr(self._identifier, "refit", None)
        if refit and callable(refit_now):
            try:
                refit_now()
            except (GenBacklashError, ArithmeticError, np.linalg.LinAlgError) as err:
                self._drop("identifier_error", f"identifier: {err}")
        if self._now is None:
            return outputs
        now = self._now
        est = self.estimate
        if est.available:
            outputs.append(Output("estimate", estimate_message(est), now, est))
        self._checkpoint(now)
        outputs.append(self.diagnostics(now))
        return outputs

    def diagnostics(self, stamp_ns: int, *, stale: bool = False) -> Output:
        """A ``diagnostics`` output now (the periodic ones come by themselves); resets the
        per-report drop counts. ``stale`` reports level STALE (e.g. a transport's wall-clock
        watchdog when no data arrive)."""
        est = self.estimate
        level = level_of(est.state)
        parts = [f"{est.state.value}: {est.reason}" if est.reason else est.state.value]
        if self.estimate is self._prior:
            parts.insert(0, "using the checkpoint's estimate until the identifier converges")
        elif self.using_checkpoint:
            parts.insert(0, "continuing from the checkpoint's estimate")
        health = self._health.report(stamp_ns)
        passing = health.passing
        level = max(level, health.level)
        parts.extend(health.parts)
        loud = {k: n for k, n in self._period_drops.items() if k not in _QUIET_DROPS}
        if loud:
            level = max(level, DiagnosticStatus.WARN)
            listed = "; ".join(
                f"{n} {k.replace('_', ' ')} (last: {self._period_reasons[k]})"
                for k, n in loud.items()
            )
            parts.append(f"dropped since the last report: {listed}")
        if self._period_problems:
            level = max(level, DiagnosticStatus.WARN)
            parts.extend(self._period_problems)
        if stale:
            level = DiagnosticStatus.STALE
            parts.insert(0, "no data")
        source = "checkpoint" if self.using_checkpoint else "identifier"
        own = self._identifier.estimate
        extra = [
            ("estimate_source", source if est.available else "none"),
            ("identifier_state", own.state.value),
            ("identifier_confidence", format(own.confidence, ".3g")),
            ("compensation_weight", format(0.0 if passing else self._weight(est), ".3g")),
            ("faults", ",".join(health.active) or "none"),
            ("commands", str(self._commands)),
            ("encoder_messages", str(self._encoders)),
            ("compensated_commands", str(self._compensated)),
            ("identifier_samples", str(self._samples)),
            ("checkpoints", str(self._checkpoints)),
            ("checkpoint_errors", str(self._checkpoint_errors)),
        ]
        extra += [(f"dropped_{k}", str(n)) for k, n in self._dropped.items()]
        saved = self._last_checkpoint_ns
        extra.append(("last_checkpoint_s", "none" if saved is None else f"{saved / 1e9:.3f}"))
        if self.warm_start_note:
            extra.append(("warm_start", self.warm_start_note))
        self._period_drops = {}
        self._period_reasons = {}
        self._period_problems = []
        hardware = self._params.joint
        message = diagnostic_array(
            stamp_ns,
            est,
            level=level,
            message="; ".join(parts),
            hardware_id=hardware,
            extra=extra,
        )
        return Output("diagnostics", message, stamp_ns, est)

    # ------------------------------------------------------------------ compensation

    def _weight(self, est: Estimate) -> float:
        if not self._params.compensate or est.model is None:
            return 0.0
        return self._options.weight(est.confidence)

    def _compensate(self, value: float, stamp: int) -> float:
        """The command to send at ``stamp`` for the desired ``value`` (always finite).

        While a fault is active the compensator passes ``value`` through (confidence 0: the
        limits still hold and its modelled load follows what is sent)."""
        if not self._params.compensate:
            return value
        est = self.estimate
        if est is not self._comp_estimate:
            self._refresh_compensator(est, value)
        comp = self._comp
        if comp is None:
            return self._limit(value)
        health = self._health
        confidence = 0.0 if health.faults and health.passing_through(stamp) else est.confidence
        sent = comp.step(value, confidence)
        return sent if math.isfinite(sent) else self._limit(value)

    def _refresh_compensator(self, est: Estimate, value: float | None) -> None:
        """Give the compensator the model of ``est`` (creating it at the first model).

        Runs after each identifier feed, so that a command rarely pays for the inversion
        plan of a new model. A model that cannot be inverted keeps the previous one.
        """
        self._comp_estimate = est
        model = est.model
        if model is None:
            return
        comp = self._comp
        try:
            if comp is None:
                # the load where the encoder saw it last (else where it is wanted), the
                # motor at the last command sent (else mid-gap: the load at rest)
                opts = self._options
                x0 = self._last_y if self._last_y is not None else value
                if x0 is None:
                    return
                last = self._last_sent
                u0 = None if last is None else min(max(last, opts.u_min), opts.u_max)
                self._comp = InverseBacklash(model, opts, x0, u0)
            elif model != comp.model:
                comp.set_model(model)
        except GenBacklashError as err:
            self._problem(f"compensator kept its previous model: {err}")

    def _limit(self, value: float) -> float:
        """Pass-through within the output limits and the rate limit (no model yet)."""
        opts = self._options
        u = value
        last = self._last_sent
        if last is not None:
            u = min(max(u, last - opts.max_rate), last + opts.max_rate)
        return min(max(u, opts.u_min), opts.u_max)

    # ------------------------------------------------------------------ alignment

    def _horizon(self, final: bool) -> int | None:
        """Latest sample time whose command is known (None: nothing final yet)."""
        last_enc = self._last_enc_ns
        if last_enc is None:
            return None
        if final:
            return last_enc
        horizon = last_enc - self._wait
        if self._last_cmd_ns is not None and self._last_cmd_ns > horizon:
            horizon = self._last_cmd_ns
        return horizon

    def _feed(self, final: bool = False) -> None:
        """Feed every final sample to the identifier (see the module notes)."""
        self._feed_at_count = len(self._enc_t) + self._batch
        if self._now is not None:
            self._next_feed_ns = self._now + self._batch_ns
            self._update_due()
        horizon = self._horizon(final)
        if horizon is None or not self._enc_t:
            return
        if not final and self._now is not None:  # equal readings wait: the encoder may be stuck
            horizon = self._health.feed_horizon(horizon, self._now)
        if self._grid_ns:
            times, ys, held, marks = self._grid_samples(horizon)
        else:
            count = bisect.bisect_right(self._enc_t, horizon)
            if count == 0:
                return
            times = held = np.array(self._enc_t[:count], dtype=np.int64)
            ys = np.array(self._enc_y[:count])
            marks = np.array(self._enc_mark[:count], dtype=bool)
            del self._enc_t[:count], self._enc_y[:count], self._enc_mark[:count]
            self._feed_at_count = len(self._enc_t) + self._batch
        if times.size == 0:
            return
        if not self._cmd_t:
            self._drop("before_first_command", "samples before the first command", times.size)
            self._fed_last_t = None
            return
        # the sample rule before anything is taken out (see the module notes)
        period = float(self._grid_ns) if self._grid_ns else self._period.value
        breaks = link_breaks(held, period, previous_ns=self._fed_last_t, marks=marks)
        k = np.searchsorted(np.array(self._cmd_t, dtype=np.int64), times, side="right") - 1
        early = int(np.count_nonzero(k < 0))
        if early:
            self._drop("before_first_command", "samples before the first command", early)
            breaks, _ = keep_breaks(breaks, k >= 0)  # the samples before it were taken out
            k, ys, times, held = k[early:], ys[early:], times[early:], held[early:]
        if k.size == 0:
            self._fed_last_t = None
            return
        us = np.array(self._cmd_u)[k]
        keep = int(k[-1])  # the command holding at the last sample, and later ones
        if keep:
            del self._cmd_t[:keep], self._cmd_u[:keep]
        kept = self._health.screen(times, us, ys, self.estimate)
        last_t: int | None = int(held[-1])
        if kept is not None:
            breaks, tail = keep_breaks(breaks, kept)
            us, ys, held = us[kept], ys[kept], held[kept]
            last_t = None if tail or held.size == 0 else int(held[-1])
        self._fed_last_t = last_t
        if us.size == 0:
            return
        try:
            self._identifier.update_many(us, ys, breaks=breaks)
        except (GenBacklashError, ArithmeticError, np.linalg.LinAlgError) as err:
            self._drop("identifier_error", f"identifier: {err}", int(us.size))
            self._fed_last_t = None  # what the identifier kept of the batch is unknown
            return
        self._samples += int(us.size)
        if self._params.compensate:
            est = self.estimate
            if est is not self._comp_estimate:
                self._refresh_compensator(est, None)

    def _grid_samples(self, horizon: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Grid times up to ``horizon`` (and the latest encoder time) with the held encoder:
        ``(times, readings, stamps of the readings held, their marks)``."""
        period = self._grid_ns
        enc_t = self._enc_t
        if self._next_grid_k is None:
            self._next_grid_k = -(-enc_t[0] // period)  # first grid point at/after the data
        first = self._next_grid_k
        last = min(horizon, enc_t[-1]) // period
        if last < first:
            none = np.zeros(0, dtype=np.int64)
            return none, np.zeros(0), none, np.zeros(0, dtype=bool)
        times = np.arange(first, last + 1, dtype=np.int64) * period
        stamps = np.array(enc_t, dtype=np.int64)
        j = np.searchsorted(stamps, times, side="right") - 1
        ys = np.array(self._enc_y)[j]
        marks = np.array(self._enc_mark, dtype=bool)[j]
        self._next_grid_k = last + 1
        keep = int(j[-1])  # the encoder reading holding at the last grid point, and later
        if keep:
            del self._enc_t[:keep], self._enc_y[:keep], self._enc_mark[:keep]
        self._enc_mark[0] = False  # held already: its mark has broken the chain there
        self._feed_at_count = len(self._enc_t) + self._batch
        return times, ys, stamps[j], marks

    def _trim_commands(self) -> None:
        """Bound the command history when no encoder data consume it.

        Keeps the commands a pending encoder reading may need, and those of the last
        ``command_wait_ns`` (a reading later than that would be more than the wait late).
        """
        oldest = self._cmd_t[-1] - self._wait
        if self._enc_t:
            oldest = min(oldest, self._enc_t[0])
        cut = bisect.bisect_right(self._cmd_t, oldest) - 1  # keep the one holding at oldest
        if cut > 0:
            del self._cmd_t[:cut], self._cmd_u[:cut]

    # ------------------------------------------------------------------ the data clock

    def _schedule(self, now: int) -> None:
        self._next_estimate = _next_multiple(now, self._publish_ns)
        self._next_diagnostics = _next_multiple(now, DIAGNOSTICS_PERIOD_NS)
        self._next_checkpoint = _next_multiple(now, self._checkpoint_ns)
        self._next_feed_ns = now + self._batch_ns
        self._update_due()

    def _update_due(self) -> None:
        due = min(self._next_estimate, self._next_diagnostics, self._next_feed_ns)
        if self._checkpoint_path is not None:
            due = min(due, self._next_checkpoint)
        self._next_due = due

    def _advance(self, stamp: int, outputs: list[Output], *, heavy: bool) -> None:
        """Move the data clock to ``stamp``; append the periodic outputs now due.

        Only ``heavy`` calls (encoder messages) feed the identifier and write checkpoints,
        so that a command's compensated command never waits for either.
        """
        now = self._now
        if now is None:
            self._now = stamp
            self._schedule(stamp)
            return
        if stamp > now:
            self._now = now = stamp
        if now < self._next_due:
            return
        if heavy and (now >= self._next_feed_ns or now >= self._next_estimate):
            self._feed()
        if now >= self._next_estimate:
            est = self.estimate
            if est.available:
                outputs.append(Output("estimate", estimate_message(est), now, est))
            self._next_estimate = _next_multiple(now, self._publish_ns)
        if heavy and self._checkpoint_path is not None and now >= self._next_checkpoint:
            self._checkpoint(now)
            self._next_checkpoint = _next_multiple(now, self._checkpoint_ns)
        if now >= self._next_diagnostics:
            outputs.append(self.diagnostics(now))
            self._next_diagnostics = _next_multiple(now, DIAGNOSTICS_PERIOD_NS)
        self._update_due()

    def _checkpoint(self, now: int) -> None:
        path = self._checkpoint_path
        est = self._identifier.estimate
        if path is None or not est.available:
            return
        try:
            self._writer(path, Checkpoint(est, now))
        except (CheckpointError, OSError) as err:
            self._checkpoint_errors += 1
            self._problem(f"checkpoint not saved: {err}")
            return
        self._checkpoints += 1
        self._last_checkpoint_ns = now

    # ------------------------------------------------------------------ faults (see health.py)

    def _reanchor(self, stream: str, stamp: int, last: int, back: int) -> None:
        """Restart alignment and the data clock at ``stamp`` after a clock jump back (by
        about ``back``) seen on ``stream`` after its last time ``last``."""
        self._feed(final=True)
        self._enc_t.clear()
        self._enc_y.clear()
        self._enc_mark.clear()
        self._mark_next = False
        self._fed_last_t = None  # a new time line: its first sample breaks
        self._next_grid_k = None
        if self._cmd_u:  # the last command is held into the new time line
            self._cmd_t, self._cmd_u = [stamp - 1], [self._cmd_u[-1]]
            self._last_cmd_ns = stamp - 1
        else:
            self._cmd_t, self._cmd_u = [], []
            self._last_cmd_ns = None
        self._last_enc_ns = None
        self._now = None  # the next accepted message restarts the schedule
        self._health.reanchored(stream, stamp, last, back)

    def _discard_after(self, since: int) -> int:
        """Drop the pending encoder readings after ``since`` (a stuck encoder's, the first
        equal reading kept); how many there were."""
        cut = bisect.bisect_right(self._enc_t, since)
        held = len(self._enc_t) - cut
        if held:
            del self._enc_t[cut:], self._enc_y[cut:], self._enc_mark[cut:]
            self._mark_next = True  # the next reading kept follows those taken out
        return held

    # ------------------------------------------------------------------ problems

    def _drop(self, key: str, reason: str, count: int = 1) -> None:
        if key == "encoder_invalid":  # a reading taken out: the next one breaks the chain
            self._mark_next = True
        self._dropped[key] += count
        self._period_drops[key] = self._period_drops.get(key, 0) + count
        self._period_reasons[key] = reason
        if key in _ENCODER_REJECTS:
            self._health.encoder_rejected(count, reason)
        if key not in _QUIET_DROPS:
            self._last_problem = reason
            # the drop report says why
            self._health.fault(key, DiagnosticStatus.WARN, "", self._now)

    def _note(self, text: str) -> None:
        """``text`` is the latest problem (a fault's reason)."""
        self._last_problem = text

    def _problem(self, text: str) -> None:
        if text not in self._period_problems:
            self._period_problems.append(text)
        self._last_problem = text
