"""The message-level node logic shared by every transport and by bag replay.

:class:`BacklashPipeline` takes command and encoder messages (:mod:`genbacklash_ros.node.messages`)
with the time they were received, and returns what to publish as :class:`Output` events --
the compensated command, the estimate, the diagnostics -- so a transport (rclpy, DDS) or the
replay only converts and publishes. It imports no transport and reads no clock: every decision
is taken on the data's own time, so a replay of a bag is deterministic and is the node.

Stages
------
Data flow one way through small stages, each a module of its own; a stage takes the
previous stage's output and returns its own, and none calls back into the pipeline::

    command  -> align (time, order) -> health check -> compensate ----------> publish
    encoder  -> align (time, order) -> health check -> pending readings
    pending  -> align.take (final samples + commands) -> screen (spikes, gaps, sample rule)
             -> identify worker (submit; results polled on every message) -> estimate in use
    data clock -> publish schedule (estimate, diagnostics, checkpoint) -> outputs

* :mod:`~genbacklash_ros.node.align` -- :class:`~genbacklash_ros.node.align.Aligner`;
* :mod:`~genbacklash_ros.node.health` and :mod:`~genbacklash_ros.node.screen` -- the faults
  and the samples to keep (events returned, never called back);
* :mod:`~genbacklash_ros.node.identify` -- the worker that runs the identifier off the message
  path (:class:`~genbacklash_ros.node.identify.SyncWorker` for replay: deterministic;
  :class:`~genbacklash_ros.node.identify.ThreadWorker` for live transports: a refit never
  delays a compensated command) and the estimate in use;
* :mod:`~genbacklash_ros.node.compensate` -- the inverse compensator;
  :mod:`~genbacklash_ros.node.judges` -- the compensation guard and the measured tracking
  (:mod:`~genbacklash_ros.node.tracking_stage`) over the model in use, which set how much
  of the inverse it applies;
* :mod:`~genbacklash_ros.node.publish`, :mod:`~genbacklash_ros.node.ledger` and
  :mod:`~genbacklash_ros.node.silence` -- the data clock, the counters and problems, and the
  streams' silences that ``/diagnostics`` reports;
  :mod:`~genbacklash_ros.node.status_report` -- the ``/diagnostics`` status built from them;
* :mod:`~genbacklash_ros.node.outputs` -- what the pipeline returns (:class:`Output`, ...);
* :mod:`~genbacklash_ros.node.batch` and :mod:`~genbacklash_ros.node.stretch` -- the batch
  form (:meth:`BacklashPipeline.on_batch`): a block's facts worked out once, and its quiet
  stretches found and taken in one step.

:class:`BacklashPipeline` is the facade over them all: it owns the stages, routes each
message through them in the order above, and is what every transport and the replay call.

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
* **Batches.** Final samples are handed to the identify worker on an encoder message when
  ``batch`` encoder messages are pending, when the data clock is ``batch_ns`` past the last
  feed, or an estimate is due. With the synchronous worker (replay) the identifier runs
  then, so the estimate the compensator uses is at most about one batch old and the same on
  every run; with the thread worker (live) it runs beside the handlers and its estimate is
  taken at the next message after it is ready. A command message never feeds nor
  checkpoints: its compensated command costs one compensator step (tens of microseconds),
  whatever the identifier costs.
* **Identifier input.** The raw command, or with ``compensation_in_loop`` the compensated
  command that was sent (what the drivetrain then really gets). With ``gear_input =
  "motor_encoder"`` (dual encoders) the motor encoder's reading: motor messages
  (:meth:`BacklashPipeline.on_motor`) are a third stream, each encoder reading is paired with
  the motor reading of its stamp (:func:`~genbacklash_ros.node.sample_rule.paired_keep`; a
  reading whose motor reading was lost is taken out as a lost reading, counted as
  ``motor_missing``), a sample is final once a motor reading at or after it (or
  ``command_wait_ns`` of encoder time) has come, and the settling rule (``settle_time``) does
  not apply: the rows pair the gear's real input with its output, however long the servo
  takes to answer a command. The commands still arrive and each is compensated: the
  identified backlash maps the motor to the load, so the compensated command is its inverse
  at the desired load position (the servo makes the motor follow the command).
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
  to the encoder's period or a multiple of it. With ``model: backlash`` (rate independent),
  a break that only lost readings made -- up to
  :data:`~genbacklash_core.samples.MAX_BRIDGED`, on the encoder's own times -- is lifted
  where the commands in force over the gap were monotone
  (:func:`~genbacklash_ros.node.screen.bridged`, the rule of
  :func:`~genbacklash_core.samples.bridge_lost`): the readings around it are consecutive
  states.

Outputs
-------
* one ``compensated_command`` per accepted command message, of the command's type and time,
  computed by :class:`~genbacklash_core.InverseBacklash` with the current estimate and its
  confidence (the raw command when ``compensate`` is false; limited but uncorrected while
  there is no model). The live transports take a command in two calls,
  :meth:`BacklashPipeline.answer` (the compensated command alone) and, once it is published,
  :meth:`BacklashPipeline.periodic` (what it made due): the same outputs as
  :meth:`BacklashPipeline.on_command`, the answer never waiting for an estimate or a report
  to be built;
* ``estimate`` every ``1 / publish_rate`` of data time while an estimate exists;
* ``diagnostics`` every second of data time: OK while converging or converged, WARN while
  warming up, without excitation or when messages were dropped since the last report (the
  reasons are in the message), ERROR when diverged.

The estimate is checkpointed every ``checkpoint_period`` of data time when
``checkpoint_file`` is set (and at :meth:`BacklashPipeline.finish`), and warm-started from it
at construction (:func:`~genbacklash_ros.node.checkpoint.warm_start`). With
``compensation_in_loop``, a checkpoint taken once the judge has measured compensation helping
carries the tracking without compensation for the next start's judge: the one measured live
once it holds ``min_time`` seconds, else the one this start took from its checkpoint; else
none (:meth:`~genbacklash_ros.node.tracking_stage.TrackingStage.baseline_to_store` says
when and why). A checkpoint taken while the judge holds compensation off for harm carries
that verdict, and the next start holds the model off until a new model or the retry
(:meth:`~genbacklash_ros.node.tracking_stage.TrackingStage.harm_to_store`).

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

import math
from collections.abc import Callable, Iterable
from pathlib import Path
from types import MappingProxyType
from typing import Literal, TypeAlias

import numpy as np

from genbacklash_core import Estimate, GenBacklashError, OnlineIdentifier
from genbacklash_core.guard import GuardVerdict
from genbacklash_core.measured import TrackingVerdict
from genbacklash_ros.node.align import Aligner
from genbacklash_ros.node.batch import BlockView
from genbacklash_ros.node.checkpoint import Checkpoint, CheckpointError, save_checkpoint, warm_start
from genbacklash_ros.node.compensate import CompensateStage, _no_fault

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
from genbacklash_ros.node.health import Drop, HealthEvent, StreamHealth
from genbacklash_ros.node.identify import (
    EstimateInUse,
    Identified,
    IdentifierWorker,
    Refused,
    Result,
    SyncWorker,
)
from genbacklash_ros.node.judges import CompensationJudges
from genbacklash_ros.node.ledger import ENCODER_REJECTS, QUIET_DROPS, Ledger
from genbacklash_ros.node.messages import (
    CommandMessage,
    DiagnosticStatus,
    Float64,
    Float64MultiArray,
    JointState,
    MessageError,
    compensated_command,
    estimate_message,
    read_command,
    read_encoder,
)
from genbacklash_ros.node.outputs import (
    BatchCollector,
    BatchOutputs,
    Output,
    PipelineStats,
    TopicKey,
)
from genbacklash_ros.node.parameters import NodeParameters
from genbacklash_ros.node.publish import DIAGNOSTICS_PERIOD_NS, Schedule
from genbacklash_ros.node.screen import Screen
from genbacklash_ros.node.silence import SilentStreams
from genbacklash_ros.node.status_report import servo_summary, status_output
from genbacklash_ros.node.stretch import QuietStretches
from genbacklash_ros.node.tracking_stage import STORE_RATIO as STORE_RATIO

__all__ = [
    "COMMAND_WAIT_NS",
    "DIAGNOSTICS_PERIOD_NS",
    "FAULT_HOLD_NS",
    "STORE_RATIO",
    "BacklashPipeline",
    "BatchOutputs",
    "CheckpointWriter",
    "Output",
    "PipelineStats",
    "TopicKey",
    "WorkerFactory",
]

CheckpointWriter: TypeAlias = Callable[[Path, Checkpoint], object]
WorkerFactory: TypeAlias = Callable[[OnlineIdentifier], IdentifierWorker]
"""Makes the identify stage's worker for an identifier (``SyncWorker``, ``ThreadWorker``)."""

COMMAND_WAIT_NS = 100_000_000  # encoder time after which a sample's command counts as held
BATCH_SAMPLES = 128  # encoder messages per identifier feed (at most)
BATCH_NS = 100_000_000  # data time between identifier feeds at most

_COMMAND_CLASSES: dict[str, type] = {
    "float64": Float64,
    "float64_multi_array": Float64MultiArray,
    "joint_state": JointState,
}


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
    worker : callable
        Makes the identify stage's worker from the identifier:
        :class:`~genbacklash_ros.node.identify.SyncWorker` (default: replay, tests; the same
        outputs on every run) or :class:`~genbacklash_ros.node.identify.ThreadWorker` (live
        transports: identification off the message path). Also a seam for tests.
    status_name : str
        Name of the ``/diagnostics`` status (several joints in one node: one per joint, the
        name ending in the joint's name).

    Notes
    -----
    Not thread-safe: a transport calls it from one thread (or under one lock). Read the
    module notes for the alignment rules. With a thread worker call :meth:`close` (or
    :meth:`finish`) at the end.
    """

    def __init__(
        self,
        params: NodeParameters,
        *,
        checkpoint_writer: CheckpointWriter | None = None,
        command_wait_ns: int = COMMAND_WAIT_NS,
        batch: int = BATCH_SAMPLES,
        batch_ns: int = BATCH_NS,
        worker: WorkerFactory = SyncWorker,
        status_name: str = "backlash_identifier",
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
        if not callable(worker):
            raise GenBacklashError(f"worker must make an identifier worker, got {worker!r}")
        self._status_name = str(status_name)
        self._writer: CheckpointWriter = (
            checkpoint_writer if checkpoint_writer is not None else save_checkpoint
        )
        self._wait = command_wait_ns
        self._batch = batch
        self._make_worker = worker
        self._ledger = Ledger()
        self._health = StreamHealth()
        self._silence = SilentStreams()
        self._params = params
        self._configure(params)
        self._clock = Schedule(
            publish_ns=params.publish_period_ns,
            checkpoint_ns=self._checkpoint_period(),
            feed_ns=batch_ns,
        )
        # the batch form's quiet stretches (bound to the stages at each start)
        self._stretches = QuietStretches(self._clock, self._health, self._silence, self._ledger)
        self._worker: IdentifierWorker | None = None
        # the time of a command answered by answer_value whose periodic step has not run
        # yet (periodic() runs it), and periodic outputs made but not taken yet
        self._answered: int | None = None
        self._due: list[Output] = []
        self._built_estimate: tuple[Estimate, Float64MultiArray] | None = None
        self._start(params)

    # ------------------------------------------------------------------ configuration

    def _configure(self, params: NodeParameters) -> None:
        """Settings that change without a restart."""
        self._params = params
        self._checkpoint_path = Path(params.checkpoint_file) if params.checkpoint_file else None
        self._index = params.command_index
        self._joint = params.joint
        self._command_kind = params.command_type
        self._command_class = _COMMAND_CLASSES[params.command_type]
        self._encoder_kind = params.encoder_type
        self._motor_kind = params.motor_encoder_type
        self._motor_joint = params.motor_joint_name

    def _checkpoint_period(self) -> int | None:
        return self._params.checkpoint_period_ns if self._checkpoint_path is not None else None

    def _start(self, params: NodeParameters) -> None:
        """(Re)start identification and alignment: warm start, empty stages."""
        start = warm_start(params)
        if self._worker is not None:
            self._worker.close()
        self._worker = self._make_worker(start.identifier)
        self._poll = self._worker.poll  # every message asks: one look-up less
        ident = start.identifier
        self._use = EstimateInUse(ident.estimate, start.prior, ident.from_seed)
        self._warm_start_note = start.note
        if start.problem:
            self._ledger.problem(start.note)
        self._in_loop = params.compensation_in_loop
        self._align = Aligner(
            use_header=params.stamp_source == "header",
            grid_ns=params.sample_period_ns,
            wait_ns=self._wait,
            # a backlash alone: its rows skip the servo's settling (bridged); linear dynamics
            # after the backlash model the lag themselves
            settle_ns=params.settle_ns if params.model == "backlash" else 0,
            # the servo between the command and the gear, modelled (genbacklash_core.servo)
            servo=params.servo(),
            servo_window_ns=round(params.servo_window * 1e9),
            motor=params.motor_input,  # the gear's input read by a motor encoder
        )
        self._screen = Screen(bridge=params.model == "backlash")
        self._comp = CompensateStage(params.compensator_options(), compensate=params.compensate)
        judges = CompensationJudges(params, self._comp, start)
        self._judges = judges
        self._tracking = judges.tracking  # (one look-up less)
        self._stretches.bind(
            self._align, self._comp, self._use, self._tracking, in_loop=self._in_loop
        )
        self._feed_at_count = self._batch
        self._clock.restart()

    def set_params(self, params: NodeParameters) -> None:
        """Apply new parameters (validated already, e.g. by :meth:`NodeParameters.replace`).

        Parameters marked ``restarts`` in the specs restart identification and alignment (a
        warm start from the checkpoint file when it fits); the others apply at once, the
        compensator keeping its state.
        """
        if not isinstance(params, NodeParameters):
            raise GenBacklashError(f"params must be NodeParameters, got {params!r}")
        self._settle_answered()  # the answered command's step, on the parameters it came under
        old = self._params
        self._configure(params)
        if old.restart_needed(params):
            self._start(params)  # the data clock restarts at the next message
            self._health.reset()
            self._clock.configure(
                publish_ns=params.publish_period_ns, checkpoint_ns=self._checkpoint_period()
            )
            return
        self._comp.reconfigure(params.compensator_options(), compensate=params.compensate)
        self._judges.configure(params)
        self._problems(self._comp.problems)
        self._clock.configure(
            publish_ns=params.publish_period_ns, checkpoint_ns=self._checkpoint_period()
        )

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
        """The online identifier (replaced on a restart; its worker's to call)."""
        assert self._worker is not None
        return self._worker.identifier

    @property
    def estimate(self) -> Estimate:
        """The estimate in use: the identifier's latest, or the checkpoint's until the
        identifier's own has converged or is at least as confident."""
        return self._use.current

    @property
    def guard(self) -> GuardVerdict:
        """The compensation guard's latest verdict (:mod:`genbacklash_core.guard`)."""
        return self._judges.verdict

    @property
    def measured(self) -> TrackingVerdict:
        """The measured tracking's latest verdict (:mod:`genbacklash_core.measured`)."""
        return self._tracking.verdict

    @property
    def servo(self) -> dict[str, object] | None:
        """The servo the identifier's input is modelled through (``servo_model``;
        :mod:`genbacklash_core.servo`), for /diagnostics and the replay's JSON: ``state``
        (``"fixed"``, ``"estimated"``, ``"estimating"``, ``"none"`` when auto could not
        estimate), the dead time and time constant (s) once known, the estimate's misfit
        with and without it, a ``note``. None with ``servo_model`` none.

        The compensator inverts the play on the servo's *output*: the command it sends is
        the servo output the play needs. The servo's lag is not inverted (no lead): a lead
        on held commands would amplify their steps and the encoder's noise, so the load
        trails the desired position by about the dead time plus the time constant, as it
        would without play; a caller who knows the desired path ahead may advance it by
        that much.
        """
        if self._params.servo() is None:
            return None
        return servo_summary(self._align, self._params.servo_window)

    @property
    def using_checkpoint(self) -> bool:
        """True while the estimate rests on the checkpoint: the identifier continues from it
        and still leans on it (``from_seed``), or its estimate stands in for the identifier's."""
        return self._use.using_checkpoint

    @property
    def stats(self) -> PipelineStats:
        """Counters since construction."""
        led = self._ledger
        return PipelineStats(
            led.commands,
            led.encoders,
            led.samples,
            led.compensated,
            led.checkpoints,
            led.checkpoint_errors,
            MappingProxyType(dict(led.dropped)),
            led.last_problem,
        )

    # ------------------------------------------------------------------ inputs

    def on_command(self, msg: CommandMessage, receive_ns: int) -> list[Output]:
        """A command message received at ``receive_ns``: the compensated command and any
        periodic outputs now due (:meth:`answer`, then :meth:`periodic`)."""
        answer = self.answer(msg, receive_ns)
        if answer is None:
            return self.periodic()
        return [answer, *self.periodic()]

    def answer(self, msg: CommandMessage, receive_ns: int) -> Output | None:
        """A command message received at ``receive_ns``: its compensated command alone
        (None when the message is dropped). The periodic outputs it makes due (estimate,
        diagnostics) are made by :meth:`periodic`, which a live transport calls once it has
        published the answer, so that building them never delays it; :meth:`on_command` is
        the two together."""
        self._settle_answered()
        try:
            if not isinstance(msg, self._command_class):
                raise MessageError(
                    f"expected a {self._command_class.__name__}, got {type(msg).__name__}"
                )
            kind, index, joint = self._command_kind, self._index, self._joint
            header_ns, value = read_command(msg, kind, index=index, joint=joint)
        except MessageError as err:
            self._drop("command_invalid", f"command: {err}")
            return None
        accepted = self.answer_value(header_ns, value, receive_ns)
        if accepted is None:
            return None
        stamp, sent = accepted
        out_msg = compensated_command(msg, sent, kind, index=index, joint=joint)
        return Output("compensated_command", out_msg, stamp)

    def on_command_value(
        self, header_ns: int | None, value: float, receive_ns: int
    ) -> tuple[int, float, list[Output]] | None:
        """A command already read from its message (header stamp, 0 when none): ``(time,
        compensated value, periodic outputs now due)``, or None when it is dropped.
        ``header_ns`` is None (or 0) for a message without a header.

        :meth:`on_command` is this plus the adapters; a transport that decodes messages
        itself (bag replay reads the value straight from the CDR bytes) calls it directly
        and writes the compensated value into its own copy of the message. It is
        :meth:`answer_value`, then :meth:`periodic`.
        """
        accepted = self.answer_value(header_ns, value, receive_ns)
        if accepted is None:
            return None
        return (*accepted, self.periodic())

    def answer_value(
        self, header_ns: int | None, value: float, receive_ns: int
    ) -> tuple[int, float] | None:
        """:meth:`on_command_value` without the periodic outputs: ``(time, compensated
        value)``, or None when the command is dropped. The periodic step of an accepted
        command (the data clock, the estimate and diagnostics now due) waits for
        :meth:`periodic`, or runs at the start of the next call that takes data."""
        if self._answered is not None:
            self._settle_answered()
        results = self._poll()
        if results:
            self._take_results(results)
        align, health, comp = self._align, self._health, self._comp
        self._silence.command(int(receive_ns))
        if not math.isfinite(value):
            self._drop("command_invalid", f"command: value {value} is not finite")
            return None
        stamp = align.time_of(header_ns, receive_ns)
        last = align.last_cmd_ns
        if last is not None and stamp <= last and not self._behind("command", stamp, last):
            return None
        events = health.check_command(stamp, value, int(receive_ns), comp.options)
        if events:
            self._events(events)
        sent = comp.command(
            value,
            self._use.current,
            # asked only when a model compensates; no fault active (as a rule): no closure
            passing=(lambda: health.passing_through(stamp)) if health.faults else _no_fault,
            last_y=align.last_y,
        )
        if comp.problems:
            self._problems(comp.problems)
        self._tracking.command(value, comp.last_weight)
        align.add_command(stamp, sent if self._in_loop else value)
        led = self._ledger
        led.commands += 1
        led.compensated += 1
        self._answered = stamp
        return stamp, sent

    def periodic(self) -> list[Output]:
        """The periodic outputs the last answered command made due (see :meth:`answer`), and
        any made since the last call; ``[]`` when none."""
        if self._answered is not None:
            self._settle_answered()
        if not self._due:
            return []
        outputs, self._due = self._due, []
        return outputs

    def _settle_answered(self) -> None:
        """Run the periodic step of a command answered by :meth:`answer_value` (its outputs
        kept for :meth:`periodic`): before anything else moves the pipeline on, so the step
        sees the state the command left, as if it had run in the same call."""
        stamp = self._answered
        if stamp is not None:
            self._answered = None
            self._advance(stamp, self._due, heavy=False)

    def on_batch(
        self,
        is_command: np.ndarray,
        header_ns: np.ndarray,
        values: np.ndarray,
        receive_ns: np.ndarray,
    ) -> BatchOutputs:
        """Many messages already read, in the order they came: the batch form of
        :meth:`on_command_value` and :meth:`on_encoder_value`, with the same results.

        Parameters
        ----------
        is_command : numpy.ndarray of bool
            Per message: a command (else an encoder reading).
        header_ns : numpy.ndarray of int64
            Header stamps (0: none).
        values : numpy.ndarray of float
            The values read.
        receive_ns : numpy.ndarray of int64
            Receive times.

        Returns
        -------
        BatchOutputs

        Notes
        -----
        Stretches of messages that make nothing happen but bookkeeping -- in order, on time,
        finite, no fault, no feed, no periodic output due, no stuck reading -- are found by
        bisection in what :class:`~genbacklash_ros.node.batch.BlockView` worked out once for
        the block, and taken in one step by the stages' batch methods
        (:meth:`Aligner.add_readings`, :meth:`StreamHealth.accept_readings`, ...). A stretch
        also takes the reading that feeds the identifier (it ends there) and the commands at
        which only an estimate comes due, making those steps where the per-message path
        makes them; each other message that makes something happen goes through the
        per-message path. The compensated commands and the estimates are those of the
        per-message path to the last bit (tests/ros/node/test_batch.py). With a thread
        worker the identifier's results are taken at the start of each stretch.
        """
        self._settle_answered()  # an answer_value's step first (its outputs: periodic())
        kinds = np.asarray(is_command, dtype=bool)
        view = BlockView(
            kinds,
            np.asarray(header_ns, dtype=np.int64),
            np.asarray(values, dtype=np.float64),
            np.asarray(receive_ns, dtype=np.int64),
            self._params.stamp_source == "header",
        )
        n = view.n
        out = BatchCollector(n)
        i = 0
        while i < n:
            end, ended = self._quiet(view, i, out)
            if end > i:  # a stretch taken
                i = end
                if ended or i >= n:  # the next may start right after it
                    continue
            # this message makes something happen: the per-message path
            value, received = float(view.values[i]), int(receive_ns[i])
            head = int(header_ns[i])
            if kinds[i]:
                taken = self.on_command_value(head, value, received)
                if taken is not None:
                    out.stamps[i], sent, outs = taken
                    out.sent[i] = sent
                    out.accepted[i] = True
                    out.outputs.extend((i, item) for item in outs)
            else:
                out.outputs.extend(
                    (i, item) for item in self.on_encoder_value(head, value, received)
                )
            i += 1
        return out.done()

    def _quiet(self, view: BlockView, i: int, out: BatchCollector) -> tuple[int, bool]:
        """Take the messages from ``i`` on that make nothing happen but bookkeeping in one
        step (see :meth:`on_batch` and :mod:`~genbacklash_ros.node.stretch`): where they
        end, and whether the stretch ended by itself (else the message there takes the
        per-message path)."""
        self._take_results()
        stretches = self._stretches
        end, natural, marks = stretches.find(view, i, self._feed_at_count)
        if end == i:
            return i, False
        stretches.take(view, i, end, out)
        self._stretch_steps(view, i, end, out, marks)
        return end, end == natural or end - 1 == stretches.closing

    def _stretch_steps(
        self, view: BlockView, i: int, end: int, out: BatchCollector, marks: list[int]
    ) -> None:
        """After a stretch ``i .. end - 1`` was taken: at the commands of ``marks`` the
        periodic steps due, and at the last message what the per-message path does after
        its bookkeeping (the feed when its reading brings the pending readings to the feed
        count, the periodic steps due), as that path does them."""
        e0, e1 = view.enc_before[i], view.enc_before[end]
        align, health = self._align, self._health
        outputs: list[Output] = []
        last = end - 1
        for p in marks:  # before the clock moves past them (in order)
            if p >= last:
                break
            self._advance(int(view.times[p]), outputs, heavy=False)
            out.outputs.extend((p, item) for item in outputs)
            outputs.clear()
        if last > i:
            self._clock.tick(int(view.times[i:last].max()))
        # the last message, as on_encoder_value / on_command_value end
        reading = e1 > e0 and view.enc_pos[e1 - 1] == last
        if last == self._stretches.closing:  # its reading closes the rate window
            self._events(health.close_rate_window(view.enc_t[e1 - 1]))
        if reading and align.pending >= self._feed_at_count:
            self._feed()
        self._advance(int(view.times[last]), outputs, heavy=reading)
        out.outputs.extend((last, item) for item in outputs)

    def on_encoder(self, msg: object, receive_ns: int) -> list[Output]:
        """An encoder message received at ``receive_ns``: any periodic outputs now due."""
        if self._answered is not None or self._due:  # an answer's step comes first
            return [*self.periodic(), *self.on_encoder(msg, receive_ns)]
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
        if self._answered is not None or self._due:  # an answer's step comes first
            return [*self.periodic(), *self.on_encoder_value(header_ns, value, receive_ns)]
        results = self._poll()
        if results:
            self._take_results(results)
        self._silence.encoder(int(receive_ns))
        if not math.isfinite(value):
            self._drop("encoder_invalid", f"encoder: value {value} is not finite")
            return []
        align = self._align
        stamp = align.time_of(header_ns, receive_ns)
        last = align.last_enc_ns
        if last is not None and stamp <= last:
            if not self._behind("encoder", stamp, last):
                return []
            last = None  # re-anchored: this reading starts the new time line
        stuck, discard_after, events = self._health.check_reading(
            stamp,
            last,
            value,
            align.last_y,
            int(receive_ns),
            align.cmd_t,
            align.cmd_u,
            self._use.current,
        )
        if discard_after is not None:
            pending = align.discard_after(discard_after)  # keep the first equal one
            if pending:
                self._drop("encoder_stuck", "encoder reading unchanged", pending)
        if events:
            self._events(events)
        align.add_reading(stamp, value, stuck=stuck)
        self._tracking.reading(stamp, value)
        self._ledger.encoders += 1
        outputs: list[Output] = []
        if align.pending >= self._feed_at_count:
            self._feed()
        if self._clock.tick(stamp):  # a periodic step is due (else nothing to do)
            self._step(outputs, heavy=True)
        return outputs

    def on_motor(self, msg: object, receive_ns: int) -> list[Output]:
        """A motor encoder message received at ``receive_ns`` (``gear_input =
        "motor_encoder"``; ignored otherwise): any periodic outputs now due."""
        if not self._align.motor:
            return []
        if self._answered is not None or self._due:  # an answer's step comes first
            return [*self.periodic(), *self.on_motor(msg, receive_ns)]
        try:
            header_ns, value = read_encoder(msg, self._motor_kind, joint=self._motor_joint)
        except MessageError as err:
            self._drop("motor_invalid", f"motor encoder: {err}")
            return []
        return self.on_motor_value(header_ns, value, receive_ns)

    def on_motor_value(self, header_ns: int | None, value: float, receive_ns: int) -> list[Output]:
        """A motor encoder reading already read from its message (header stamp, 0 when
        none): any periodic outputs now due (:meth:`on_motor` is this plus the adapters).

        The reading is the identifier's input (see the module notes); readings before the
        first command are not kept (the rows start there, as in batch). One not after the
        last accepted motor reading is dropped (``motor_out_of_order``; a clock jump back
        re-anchors on the command and encoder streams, the motor's following them).
        """
        align = self._align
        if not align.motor:
            return []
        if self._answered is not None or self._due:  # an answer's step comes first
            return [*self.periodic(), *self.on_motor_value(header_ns, value, receive_ns)]
        self._take_results()
        if not math.isfinite(value):
            self._drop("motor_invalid", f"motor encoder: value {value} is not finite")
            return []
        if align.last_cmd_ns is None:  # the rows start at the first command (as in batch)
            return []
        stamp = align.time_of(header_ns, receive_ns)
        last = align.last_motor_ns
        if last is not None and stamp <= last:
            self._drop("motor_out_of_order", _order_text("motor encoder", stamp, last))
            return []
        align.add_motor(stamp, value)
        outputs: list[Output] = []
        self._advance(stamp, outputs, heavy=False)
        return outputs

    def reject(self, stream: Literal["command", "encoder", "motor"], reason: str) -> None:
        """A message of ``stream`` its transport could not read (e.g. bytes that do not
        decode): counted and reported like one the adapters reject."""
        self._settle_answered()
        self._drop(f"{stream}_invalid", f"{stream}: {reason}")

    def finish(self, *, refit: bool = True) -> list[Output]:
        """End of the data (a replay's last message, a node shutting down).

        Feeds every pending sample (their commands taken as held), waits for the identify
        worker, refits the windowed identifier on its window when ``refit``, and returns the
        final estimate and diagnostics; checkpoints when a file is set.
        """
        outputs = self.periodic()  # an answered command's, not taken yet
        self._feed(final=True)
        worker = self._worker
        assert worker is not None
        worker.flush()
        self._take_results()
        if refit:
            result = worker.refit()
            if result is not None:
                self._take_results([result])
        self._judges.flush()  # the samples the guard has not judged yet
        now = self._clock.now
        if now is None:
            return outputs
        est = self.estimate
        if est.available:
            outputs.append(Output("estimate", self._estimate_message(est), now, est))
        self._checkpoint(now)
        outputs.append(self.diagnostics(now))
        return outputs

    def close(self) -> None:
        """Stop the identify worker (a thread worker's thread ends; idempotent)."""
        if self._worker is not None:
            self._worker.close()

    def diagnostics(self, stamp_ns: int, *, stale: bool = False) -> Output:
        """A ``diagnostics`` output now (the periodic ones come by themselves); resets the
        per-report drop counts. ``stale`` reports level STALE (e.g. a transport's wall-clock
        watchdog when no data arrive)."""
        est = self.estimate
        params = self._params
        # the reports that reset per-report counts, in this order
        health = self._health.report(stamp_ns)
        silent = self._silence.report(params.command_type, params.encoder_type)
        period = self._ledger.take_period()
        guard = self._judges.verdict
        measured = self._tracking.verdict
        status = self._comp.status(est, health.active if health.passing else (), guard, measured)
        return status_output(
            stamp_ns,
            est,
            use=self._use,
            health=health,
            silent=silent,
            period=period,
            ledger=self._ledger,
            guard=guard,
            measured=measured,
            status=status,
            compensate=params.compensate,
            await_guard=self._judges.await_guard,
            warm_start_note=self.warm_start_note,
            servo=self.servo,
            name=self._status_name,
            hardware_id=params.joint,
            stale=stale,
        )

    # ------------------------------------------------------------------ the stages

    def _feed(self, final: bool = False) -> None:
        """Align the final samples, screen them and hand them to the identify worker."""
        align = self._align
        self._feed_at_count = align.pending + self._batch
        self._clock.fed()
        horizon = align.horizon(final)
        now = self._clock.now
        if horizon is not None and not final and now is not None:
            horizon = self._health.feed_horizon(horizon, now)  # equal readings wait
        batch = align.take(horizon, final=final)
        self._feed_at_count = align.pending + self._batch
        if batch is None:
            return
        if batch.before_first_command:
            self._ledger.drop(
                "before_first_command",
                "samples before the first command",
                batch.before_first_command,
            )
        if batch.unpaired:
            self._ledger.drop(
                "motor_missing", "encoder readings without a motor reading", batch.unpaired
            )
        if batch.size == 0:
            return
        self._health.model_fits = self._judges.verdict.state != "off"
        screened = self._screen.run(batch, self._health, self._use.current)
        self._events(screened.events)
        if screened.size == 0:
            return
        # does compensating with the model in use help on these samples? (fades it if not;
        # its free run restarts only where the path is not known: screened.restarts)
        self._judges.judge_samples(
            screened.us,
            screened.ys,
            screened.restarts,
            self._use.current.model,
            screened.commands,
            screened.command_restarts,
        )
        assert self._worker is not None
        self._worker.submit(screened.us, screened.ys, screened.breaks)
        self._take_results()

    def _take_results(self, results: Iterable[Result] | None = None) -> None:
        """Adopt what the identify worker finished: counts, drops, the new estimate."""
        if results is None:
            assert self._worker is not None
            results = self._worker.poll()
            if not results:
                return
        adopted = None
        for result in results:
            if isinstance(result, Identified):
                self._ledger.samples += result.samples
                self._use.adopt(result.estimate, result.from_seed)
                adopted = result
            elif isinstance(result, Refused):
                self._drop("identifier_error", result.reason, result.samples)
            else:
                self._drop("identifier_behind", result.reason, result.samples)
        if adopted is not None:
            # the new model judged at once on the samples the guard remembers
            self._judges.adopt(self._use.current.model)
            self._comp.adopt(self._use.current, self._align.last_y)
            if self._comp.problems:
                self._problems(self._comp.problems)

    def _advance(self, stamp: int, outputs: list[Output], *, heavy: bool) -> None:
        """Move the data clock to ``stamp``; append the periodic outputs now due.

        Only ``heavy`` calls (encoder messages) feed the identifier and write checkpoints,
        so that a command's compensated command never waits for either.
        """
        if self._clock.tick(stamp):
            self._step(outputs, heavy=heavy)

    def _step(self, outputs: list[Output], *, heavy: bool) -> None:
        """The periodic step :meth:`_advance` found due (the data clock moved already)."""
        clock = self._clock
        now = clock.now
        assert now is not None
        due = clock.due(now)
        if heavy and (due.feed or due.estimate):
            self._feed()
        if due.estimate:
            est = self.estimate
            if est.available:
                outputs.append(Output("estimate", self._estimate_message(est), now, est))
            clock.estimate_done(now)
        if heavy and due.checkpoint:
            self._checkpoint(now)
            clock.checkpoint_done(now)
        if due.diagnostics:
            outputs.append(self.diagnostics(now))
            clock.diagnostics_done(now)
        clock.settle()

    def _estimate_message(self, est: Estimate) -> Float64MultiArray:
        """The ``estimate`` message of ``est``: built once per estimate (the messages are
        frozen; the estimate in use often stays the same over several publish periods)."""
        built = self._built_estimate
        if built is not None and built[0] is est:
            return built[1]
        message = estimate_message(est)
        self._built_estimate = (est, message)
        return message

    def _checkpoint(self, now: int) -> None:
        path = self._checkpoint_path
        est = self._use.own
        if path is None or not est.available:
            return
        led, tracking, in_loop = self._ledger, self._tracking, self._in_loop
        try:
            self._writer(
                path,
                Checkpoint(
                    est,
                    now,
                    baseline=tracking.baseline_to_store(in_loop=in_loop),
                    harm=tracking.harm_to_store(in_loop=in_loop),
                ),
            )
        except (CheckpointError, OSError) as err:
            led.checkpoint_errors += 1
            self._problem(f"checkpoint not saved: {err}")
            return
        led.checkpoints += 1
        led.last_checkpoint_ns = now

    def _behind(self, stream: str, stamp: int, last: int) -> bool:
        """A ``stream`` message stamped at or before the stream's last time ``last``: after a
        clock jump back, alignment restarts at ``stamp`` (True: take the message); otherwise
        it is dropped as a duplicate or out of order (False)."""
        back = self._health.jumped_back(stream, stamp, last)
        if back is None:
            key = f"{stream}_duplicate" if stamp == last else f"{stream}_out_of_order"
            self._drop(key, _order_text(stream, stamp, last))
            return False
        self._reanchor(stream, stamp, last, back)
        return True

    def _reanchor(self, stream: str, stamp: int, last: int, back: int) -> None:
        """Restart alignment and the data clock at ``stamp`` after a clock jump back (by
        about ``back``) seen on ``stream`` after its last time ``last``."""
        self._feed(final=True)
        self._align.reanchor(stamp)
        self._clock.restart()  # the next accepted message restarts the schedule
        self._events(self._health.reanchored(stream, stamp, last, back))

    # ------------------------------------------------------------------ problems

    def _events(self, events: list[HealthEvent]) -> None:
        """Route what the health checks found: drops to the ledger, notes as problems."""
        for event in events:
            if isinstance(event, Drop):
                self._drop(event.key, event.reason, event.count)
            else:
                self._ledger.note(event.text)

    def _drop(self, key: str, reason: str, count: int = 1) -> None:
        if key == "encoder_invalid":  # a reading taken out: the next one breaks the chain
            self._align.reading_taken_out()
        self._ledger.drop(key, reason, count)
        if key in ENCODER_REJECTS:
            self._health.encoder_rejected(count, reason)
        if key not in QUIET_DROPS:  # the drop report says why
            self._health.fault(key, DiagnosticStatus.WARN, "", self._clock.now)

    def _problems(self, texts: list[str]) -> None:
        for text in texts:
            self._problem(text)
        texts.clear()

    def _problem(self, text: str) -> None:
        self._ledger.problem(text)
