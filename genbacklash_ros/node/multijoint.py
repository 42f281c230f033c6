"""Several joints through one node: one :class:`BacklashPipeline` per joint, one message each.

:class:`MultiJointPipeline` holds one :class:`~genbacklash_ros.node.pipeline.BacklashPipeline`
per joint of a :class:`~genbacklash_ros.node.joints.JointSet` and takes the node's messages
whole: each command message (a Float64MultiArray, or a JointState) and each encoder
JointState goes to every joint's pipeline, which reads its own element (``command_index``)
or joint (``joint``) as a single-joint node would; the joints' compensated values are then
written into *one* copy of the command message, the other elements passing through
unchanged. Every joint keeps its own alignment, health checks, identifier, estimate,
compensator and guard: a fault on one joint (a missing name, a stuck reading) passes only
that joint's element through.

Outputs: one ``compensated_command`` per command message that at least one joint accepted
(an element its joint dropped -- out of range, out of order for that joint -- passes
through); each joint's ``estimate`` with :attr:`Output.joint` set (the transports publish it
on ``~/<joint>/estimate``); each joint's periodic ``diagnostics`` as they come (a
DiagnosticArray with the joint's status, named ``backlash_identifier: <joint>``), and
:meth:`MultiJointPipeline.diagnostics` (the transports' wall-clock STALE report) one array
with a status per joint.

Both transports (rclpy, DDS) build their pipeline with :func:`make_pipeline`: a
:class:`BacklashPipeline` for a single joint (the default, unchanged), this class for
``joints``.

Examples
--------
>>> from genbacklash_ros.node.joints import JointSet
>>> from genbacklash_ros.node.messages import Float64MultiArray, Header, JointState, Time
>>> js = JointSet.from_mapping({"joints": ["a", "b"], "command_indices": [2, 0]})
>>> pipe = MultiJointPipeline(js)
>>> pipe.on_command(Float64MultiArray(data=(0.1, 0.5, 0.2)), 1_000_000)[0].message.data
(0.1, 0.5, 0.2)
>>> out = pipe.on_encoder(JointState(Header(Time.from_ns(2_000_000)), ("b", "a"), (0.1, 0.2)),
...                       2_100_000)
>>> [p.stats.encoder_messages for p in pipe.pipelines.values()]
[1, 1]
"""

from __future__ import annotations

import math
from types import MappingProxyType
from typing import Literal

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.identify import SyncWorker
from genbacklash_ros.node.joints import JointSet
from genbacklash_ros.node.messages import (
    CommandMessage,
    DiagnosticArray,
    DiagnosticStatus,
    Float64MultiArray,
    Header,
    JointState,
    MessageError,
    Time,
    compensated_command,
    read_command,
)
from genbacklash_ros.node.parameters import NODE_NAME, NodeParameters
from genbacklash_ros.node.pipeline import (
    BacklashPipeline,
    CheckpointWriter,
    Output,
    PipelineStats,
    WorkerFactory,
)

__all__ = ["MultiJointPipeline", "joint_status_name", "make_pipeline"]


def joint_status_name(joint: str) -> str:
    """The ``/diagnostics`` status name of one joint's pipeline (ends in the joint's name).

    >>> joint_status_name("elbow")
    'backlash_identifier: elbow'
    """
    return f"{NODE_NAME}: {joint}"


class MultiJointPipeline:
    """One pipeline per joint behind one command and one encoder stream.

    Parameters
    ----------
    joints : JointSet
        With ``joints`` set (:attr:`JointSet.multi`).
    checkpoint_writer, worker
        As for :class:`BacklashPipeline`, for every joint's pipeline.

    Notes
    -----
    Not thread-safe, like :class:`BacklashPipeline`. With a thread worker call :meth:`close`
    (or :meth:`finish`) at the end.
    """

    def __init__(
        self,
        joints: JointSet,
        *,
        checkpoint_writer: CheckpointWriter | None = None,
        worker: WorkerFactory = SyncWorker,
    ) -> None:
        if not isinstance(joints, JointSet) or not joints.multi:
            raise GenBacklashError(
                f"a MultiJointPipeline needs a JointSet with joints, got {joints!r}"
            )
        self._joints = joints
        self._kind = joints.base.command_type
        self._pipes: dict[str, BacklashPipeline] = {}
        try:
            for params in joints.per_joint:
                self._pipes[params.joint] = BacklashPipeline(
                    params,
                    checkpoint_writer=checkpoint_writer,
                    worker=worker,
                    status_name=joint_status_name(params.joint),
                )
        except BaseException:
            self.close()
            raise
        self._command_class = Float64MultiArray if self._kind != "joint_state" else JointState
        # per joint, in ``joints`` order: (name, pipeline, command index), fixed while the
        # node runs (set_joint_set), so that a message's pass over the joints looks up nothing
        self._slots = tuple(
            (params.joint, self._pipes[params.joint], params.command_index)
            for params in joints.per_joint
        )
        self._places = _Places(tuple(self._pipes))

    # ------------------------------------------------------------------ properties

    @property
    def joint_set(self) -> JointSet:
        """The joints and their parameters in use."""
        return self._joints

    @property
    def params(self) -> NodeParameters:
        """The node-level parameters (each joint's: :attr:`pipelines`)."""
        return self._joints.base

    @property
    def pipelines(self) -> MappingProxyType[str, BacklashPipeline]:
        """Joint name -> its pipeline, in ``joints`` order."""
        return MappingProxyType(self._pipes)

    @property
    def warm_start_note(self) -> str:
        """What each joint's start made of its checkpoint file (one line per joint that used
        one; "" when none did)."""
        return "; ".join(
            f"{j}: {p.warm_start_note}" for j, p in self._pipes.items() if p.warm_start_note
        )

    @property
    def stats(self) -> PipelineStats:
        """Counters summed over the joints (messages are counted once per joint)."""
        per = [p.stats for p in self._pipes.values()]
        dropped: dict[str, int] = {}
        for s in per:
            for k, n in s.dropped.items():
                dropped[k] = dropped.get(k, 0) + n
        last = next((s.last_problem for s in reversed(per) if s.last_problem), "")
        return PipelineStats(
            sum(s.commands for s in per),
            sum(s.encoder_messages for s in per),
            sum(s.samples for s in per),
            sum(s.compensated for s in per),
            sum(s.checkpoints for s in per),
            sum(s.checkpoint_errors for s in per),
            MappingProxyType(dropped),
            last,
        )

    # ------------------------------------------------------------------ parameters

    def set_joint_set(self, joints: JointSet) -> None:
        """Apply new parameters (the same joints, indices and message types; validated)."""
        if joints.joints != self._joints.joints or joints.command_indices != (
            self._joints.command_indices
        ):
            raise GenBacklashError("'joints' and 'command_indices' are fixed while the node runs")
        for params in joints.per_joint:
            pipe = self._pipes[params.joint]
            if params != pipe.params:
                pipe.set_params(params)
        self._joints = joints

    # ------------------------------------------------------------------ inputs

    def on_command(self, msg: CommandMessage, receive_ns: int) -> list[Output]:
        """A command message: one compensated command (every joint's element compensated,
        the others passing through) and the joints' periodic outputs now due
        (:meth:`answer`, then :meth:`periodic`)."""
        answer = self.answer(msg, receive_ns)
        if answer is None:
            return self.periodic()
        return [answer, *self.periodic()]

    def answer(self, msg: CommandMessage, receive_ns: int) -> Output | None:
        """A command message: its one compensated command alone (None when no joint took
        it); the joints' periodic outputs it makes due come from :meth:`periodic` (as
        :meth:`BacklashPipeline.answer`), so that a live transport publishes the answer
        before any joint builds its estimate or diagnostics."""
        if not isinstance(msg, self._command_class):
            reason = f"expected a {self._command_class.__name__}, got {type(msg).__name__}"
            for pipe in self._pipes.values():
                pipe.reject("command", reason)
            return None
        kind = self._kind
        array = _finite_data(msg) if kind == "float64_multi_array" else None
        data = None if array is None else list(array)
        size = 0 if data is None else len(data)
        out_msg: CommandMessage = msg
        stamp: int | None = None
        for joint, pipe, index in self._slots:
            if data is not None and index < size:  # every element a finite float: read it
                header_ns: int | None = None
                value = data[index]
            else:  # the adapter says why (or reads a JointState command)
                try:
                    header_ns, value = read_command(msg, kind, index=index, joint=joint)
                except MessageError as err:
                    pipe.reject("command", str(err))
                    continue
            taken = pipe.answer_value(header_ns, value, receive_ns)
            if taken is None:
                continue
            at, sent = taken
            stamp = at if stamp is None else stamp
            if data is not None:
                data[index] = float(sent)
            else:
                out_msg = compensated_command(out_msg, sent, kind, index=index, joint=joint)
        if stamp is None:
            return None
        if data is not None:
            assert isinstance(msg, Float64MultiArray)
            out_msg = Float64MultiArray(msg.layout, tuple(data))
        return Output("compensated_command", out_msg, stamp)

    def periodic(self) -> list[Output]:
        """Every joint's :meth:`BacklashPipeline.periodic`, in joint order, each tagged with
        its joint."""
        outputs: list[Output] = []
        for joint, pipe, _ in self._slots:
            due = pipe.periodic()
            if due:
                outputs.extend(_tagged(due, joint))
        return outputs

    def on_motor(self, msg: object, receive_ns: int) -> list[Output]:
        """A motor encoder message: nothing (``joints`` takes no motor encoder, see
        :class:`~genbacklash_ros.node.joints.JointSet`; one node per joint does)."""
        return []

    def on_encoder(self, msg: object, receive_ns: int) -> list[Output]:
        """An encoder JointState: each joint's reading to its pipeline; the periodic outputs
        now due."""
        outputs: list[Output] = []
        places = self._places.of(msg)
        if places is None:  # not a plain JointState: the adapter reads it, or says why not
            for joint, pipe, _ in self._slots:
                due = pipe.on_encoder(msg, receive_ns)
                if due:
                    outputs.extend(_tagged(due, joint))
            return outputs
        assert isinstance(msg, JointState)
        stamp = msg.header.stamp.to_ns()
        position = msg.position
        isfinite = math.isfinite
        for (joint, pipe, _), k in zip(self._slots, places, strict=True):
            value = position[k] if k >= 0 else None
            if type(value) is float and isfinite(value):  # a plain reading: the value itself
                due = pipe.on_encoder_value(stamp, value, receive_ns)
            else:  # the adapter says why it cannot read it
                due = pipe.on_encoder(msg, receive_ns)
            if due:
                outputs.extend(_tagged(due, joint))
        return outputs

    def reject(self, stream: Literal["command", "encoder", "motor"], reason: str) -> None:
        """A message its transport could not read: counted by every joint."""
        for pipe in self._pipes.values():
            pipe.reject(stream, reason)

    def finish(self, *, refit: bool = True) -> list[Output]:
        """End of the data: every joint's :meth:`BacklashPipeline.finish`, in joint order."""
        outputs: list[Output] = []
        for joint, pipe in self._pipes.items():
            outputs.extend(_tagged(pipe.finish(refit=refit), joint))
        return outputs

    def close(self) -> None:
        """Stop every joint's identify worker (idempotent)."""
        for pipe in self._pipes.values():
            pipe.close()

    def diagnostics(self, stamp_ns: int, *, stale: bool = False) -> Output:
        """One ``diagnostics`` output now holding every joint's status, in joint order."""
        statuses: list[DiagnosticStatus] = []
        for pipe in self._pipes.values():
            message = pipe.diagnostics(stamp_ns, stale=stale).message
            assert isinstance(message, DiagnosticArray)
            statuses.extend(message.status)
        merged = DiagnosticArray(Header(Time.from_ns(stamp_ns)), tuple(statuses))
        return Output("diagnostics", merged, stamp_ns)


def _finite_data(msg: object) -> tuple[float, ...] | None:
    """A Float64MultiArray's data when it is a non-empty tuple of finite floats (what
    :func:`~genbacklash_ros.node.messages.read_command` would accept at any index within
    it), else None (the adapter then reads each joint's element and says what is wrong)."""
    data = getattr(msg, "data", None)
    if not isinstance(data, tuple) or not data:
        return None
    isfinite = math.isfinite
    return data if all(type(v) is float and isfinite(v) for v in data) else None


class _Places:
    """Where each joint's position is in a JointState: looked up once per name tuple.

    Parameters
    ----------
    joints : tuple of str
        The joints, in the order :meth:`of` gives their places.

    Examples
    --------
    >>> places = _Places(("a", "b"))
    >>> places.of(JointState(Header(), ("b", "c", "b"), (0.1, 0.2, 0.3)))
    (-1, 0)
    >>> places.of(JointState(Header(), ("b",), ())) is None  # what the adapter reads one by one
    True
    """

    __slots__ = ("_joints", "_names", "_places")

    def __init__(self, joints: tuple[str, ...]) -> None:
        self._joints = joints
        self._names: tuple[str, ...] | None = None
        self._places: tuple[int, ...] = ()

    def of(self, msg: object) -> tuple[int, ...] | None:
        """Per joint, the index of its name's first position in ``msg`` (-1: not there),
        when ``msg`` is a JointState with as many names as positions (the adapter reads it
        the same way), else None."""
        if not isinstance(msg, JointState):
            return None
        names = msg.name
        if len(names) != len(msg.position) or not names:
            return None
        if names != self._names:  # a new name tuple (the same one each message, as a rule)
            first: dict[str, int] = {}
            for k, name in enumerate(names):
                first.setdefault(name, k)  # the adapter reads a name's first position only
            self._places = tuple(first.get(joint, -1) for joint in self._joints)
            self._names = names
        return self._places


def _tagged(outputs: list[Output], joint: str) -> list[Output]:
    return [
        Output(o.topic, o.message, o.stamp_ns, o.estimate, joint)
        if o.topic != "compensated_command"
        else o
        for o in outputs
    ]


def make_pipeline(
    joints: JointSet,
    *,
    checkpoint_writer: CheckpointWriter | None = None,
    worker: WorkerFactory = SyncWorker,
) -> BacklashPipeline | MultiJointPipeline:
    """The node's pipeline: a :class:`BacklashPipeline` for a single joint (the default), a
    :class:`MultiJointPipeline` with ``joints``."""
    if joints.multi:
        return MultiJointPipeline(joints, checkpoint_writer=checkpoint_writer, worker=worker)
    return BacklashPipeline(joints.base, checkpoint_writer=checkpoint_writer, worker=worker)
