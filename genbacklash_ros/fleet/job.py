"""What runs per bag of a fleet archive: plan it, then identify, diagnose, optionally replay.

Two steps, each a plain function a Dask worker runs (picklable inputs, no database):

* :func:`inspect_bag`: the bag's content hash, its drivetrain (robot, joints) and time by the
  rule of :mod:`genbacklash_ros.fleet.archive` -- a :class:`BagPlan`. Cheap: the driver then
  skips the joints whose result is already in the database (same hash, same settings).
* :func:`analyse_bag`: per joint, the aligned samples
  (:func:`~genbacklash_ros.bags.bagio.read_aligned`), the batch identification
  (:func:`~genbacklash_core.identify_backlash` or ``identify_cascade``, with the sample
  rule's breaks) with standard deviations
  (:mod:`genbacklash_ros.fleet.uncertainty`), the discrepancy workflow
  (:func:`~genbacklash_core.diagnose.diagnose`) and, with ``replay``, the online replay through
  the node's pipeline (:func:`~genbacklash_ros.bags.replay.replay`, into a temporary bag). It
  never raises for a bad bag: every joint gets a :class:`BagResult` whose ``status`` says how
  it went and ``reason`` why.

Statuses: ``ok`` (identified, converged, free-run NRMSE at most ``max_nrmse``), ``poor_fit``
(converged, but the free-run NRMSE is above ``max_nrmse``: a wrong local solution or a
drivetrain the model does not describe; the estimate is kept, trends leave it out),
``not_converged`` (identified, the iteration did
not converge; the estimate is kept), ``no_motion`` (not enough excitation: the joint did not
move through its play), ``unreadable`` (the bag, a topic or its messages cannot be read),
``failed`` (anything else; the reason names the exception).

A recording cut part-way (a recorder killed mid-write) or corrupt after some point is not
thrown away: its readable part is analysed, as ``genbacklash replay`` keeps it, and the row
is flagged -- ``truncated`` True, ``recorded_s`` the recording's length by its
``metadata.yaml`` (None for a bare ``.mcap``, whose copy was cut off with it), and the reason
starts with ``truncated: read X of Y s`` and where the damage is.
"""

from __future__ import annotations

import hashlib
import json
import math
import tempfile
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from genbacklash_core import (
    Cascade,
    GenBacklashError,
    IdentificationResult,
    __version__,
    identify_backlash,
    identify_cascade,
)
from genbacklash_core.cascade import model_to_dict
from genbacklash_core.diagnose import DiagnoseSettings, StartStructure, diagnose
from genbacklash_core.errors import NotEnoughExcitationError
from genbacklash_core.uncertainty import parameter_covariance, play_std
from genbacklash_ros.bags.bagio import (
    COMMAND_MSGTYPES,
    ENCODER_MSGTYPES,
    AlignedSeries,
    BagError,
    BagReader,
    read_aligned,
)
from genbacklash_ros.fleet.archive import (
    ArchiveBag,
    bag_start_ns,
    content_hash,
    metadata_identity,
    recorded_duration_ns,
)
from genbacklash_ros.node.messages import JointState
from genbacklash_ros.node.parameters import NodeParameters

__all__ = [
    "STATUSES",
    "BagPlan",
    "BagResult",
    "FleetSettings",
    "JointRequest",
    "analyse_bag",
    "check_archive",
    "inspect_bag",
    "truncation_note",
]

STATUSES = ("ok", "poor_fit", "not_converged", "no_motion", "unreadable", "failed")
"""Every value of :attr:`BagResult.status`."""


@dataclass(frozen=True)
class JointRequest:
    """A joint to analyse in each bag: its ``JointState`` name (``""``: the encoder's first
    joint) and the ``Float64MultiArray`` command element (None: the node parameter
    ``command_index``)."""

    name: str = ""
    command_index: int | None = None

    def __post_init__(self) -> None:
        if self.command_index is not None and self.command_index < 0:
            raise GenBacklashError(
                f"joint {self.name!r}: the command index must be >= 0, got {self.command_index}"
            )


def _json_safe(value: Any) -> Any:
    """Non-finite floats as strings (``"inf"``), so that every database's JSON takes them."""
    if isinstance(value, float) and not math.isfinite(value):
        return repr(value)
    if isinstance(value, dict):
        return {k: _json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    return value


@dataclass(frozen=True)
class FleetSettings:
    """How each bag is analysed (the same for the whole archive).

    Attributes
    ----------
    command_topic, encoder_topic : str
        The topics read from every bag.
    params : NodeParameters
        The node's parameters: ``model``, ``degree``, ``na``, ``nb`` set the structure
        identified; ``joint``, ``command_index`` the joint when neither the path nor
        ``joints`` says; the replay uses them all.
    joints : tuple of JointRequest
        Joints to analyse in bags whose path and metadata name none (empty: ``params.joint``).
    diagnose : bool
        Run the discrepancy workflow.
    diagnose_from_params : bool
        The diagnosis starts from the structure in ``params`` (as ``genbacklash diagnose``
        does when ``model``/``degree``/``na``/``nb`` is given), else from the ideal backlash.
    validation : float
        Fraction of each record the diagnosis holds out.
    replay : bool
        Also replay the bag through the node's pipeline (the online estimate).
    max_nrmse : float
        A converged fit whose free-run NRMSE is above this is ``poor_fit``, not ``ok``.
    """

    command_topic: str = "/command"
    encoder_topic: str = "/encoder"
    params: NodeParameters = field(default_factory=NodeParameters)
    joints: tuple[JointRequest, ...] = ()
    diagnose: bool = True
    diagnose_from_params: bool = False
    validation: float = 0.3
    replay: bool = False
    max_nrmse: float = 0.02

    def __post_init__(self) -> None:
        if not self.command_topic or not self.encoder_topic:
            raise GenBacklashError("give both a command and an encoder topic")
        if self.command_topic == self.encoder_topic:
            raise GenBacklashError(
                f"the command and encoder topics must differ, both are {self.command_topic!r}"
            )
        if not 0.0 < self.validation < 1.0:
            raise GenBacklashError(f"validation must lie in (0, 1), got {self.validation}")
        if not self.max_nrmse > 0:
            raise GenBacklashError(f"max_nrmse must be > 0, got {self.max_nrmse}")

    def requests(self, path_joint: str | None) -> tuple[JointRequest, ...]:
        """The joints to analyse in a bag whose path or metadata names ``path_joint``."""
        if path_joint is not None:
            for request in self.joints:
                if request.name == path_joint:
                    return (request,)
            return (JointRequest(path_joint),)
        return self.joints or (JointRequest(self.params.joint),)

    def command_index(self, request: JointRequest) -> int:
        """The command element of ``request`` (the node parameter when it says none)."""
        if request.command_index is not None:
            return request.command_index
        return self.params.command_index

    def to_dict(self, joint: str, command_index: int) -> dict[str, Any]:
        """What decides one row's numbers (JSON values): the key of :meth:`key`."""
        params = dict(self.params.to_mapping())
        params.update(joint=joint, command_index=command_index)
        out: dict[str, Any] = _json_safe(
            {
                "command_topic": self.command_topic,
                "encoder_topic": self.encoder_topic,
                "params": params,
                "diagnose": self.diagnose,
                "diagnose_from_params": self.diagnose_from_params,
                "validation": self.validation,
                "replay": self.replay,
                "max_nrmse": self.max_nrmse,
            }
        )
        return out

    def key(self, joint: str, command_index: int) -> str:
        """SHA-256 of :meth:`to_dict`: with the bag's hash and the joint, the row's identity
        (a re-run with the same key skips the bag).

        >>> FleetSettings().key("a", 0) == FleetSettings().key("a", 0) != FleetSettings(
        ...     replay=True).key("a", 0)
        True
        """
        text = json.dumps(self.to_dict(joint, command_index), sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class BagPlan:
    """A bag, planned (:func:`inspect_bag`).

    Attributes
    ----------
    bag : ArchiveBag
    bag_hash : str
        :func:`~genbacklash_ros.fleet.archive.content_hash` (``""`` when the bag cannot be
        read at all; ``reason`` says why).
    robot : str
    joints : tuple of (str, int)
        Each joint's name (resolved: never ``""`` when the encoder could be read) and command
        element.
    recorded_ns : int or None
        The bag's time (ns since the epoch, UTC); None when neither path nor bag gives one.
    time_source : str or None
        ``"name"``, ``"directory"`` (the path) or ``"metadata"`` (the bag's first message).
    reason : str
        Why the bag could not be inspected ("" when it could).
    """

    bag: ArchiveBag
    bag_hash: str
    robot: str
    joints: tuple[tuple[str, int], ...]
    recorded_ns: int | None
    time_source: str | None
    reason: str = ""


def _first_joint(path: Path, topic: str) -> str:
    """The first joint name of the encoder's first JointState (the topic's name for a
    ``std_msgs/Float64`` encoder); ``""`` when it cannot be read."""
    try:
        with BagReader(path) as reader:
            for item in reader.messages([topic]):
                message = item.message
                if isinstance(message, JointState):
                    return message.name[0] if message.name else ""
                return topic
    except GenBacklashError:
        return ""
    return ""


def _what_is_there(root: Path, limit: int = 5) -> str:
    """A few of the entries under ``root`` (what an archive without bags holds)."""
    found: list[str] = []
    total = 0
    try:
        for path in sorted(root.rglob("*")):
            if path.is_file() and not any(part.startswith(".") for part in path.parts):
                total += 1
                if len(found) < limit:
                    found.append(path.relative_to(root).as_posix())
    except OSError:
        pass
    if not total:
        return "it holds no files"
    more = f" and {total - limit} more" if total > limit else ""
    return f"it holds {total} file{'' if total == 1 else 's'}: {', '.join(found)}{more}"


def check_archive(archive: str | Path, bags: list[ArchiveBag], settings: FleetSettings) -> None:
    """Stop before any work when the archive holds no bag, or no bag with both topics.

    The bags are opened in order until one holds ``settings.command_topic`` and
    ``settings.encoder_topic`` with supported types (the check of
    :meth:`~genbacklash_ros.bags.bagio.BagReader.topic`; usually the first bag). When none
    does, :class:`~genbacklash_core.GenBacklashError` names the topics (and types) the bags
    hold, or why none could be read. A bag that lacks them among others that have them is
    the row ``unreadable``, as before.
    """
    root = Path(archive)
    if not bags:
        raise GenBacklashError(
            f"{archive} holds no bags (rosbag2 directories with metadata.yaml, or .mcap "
            f"files); {_what_is_there(root)}"
        )
    held: dict[tuple[str, str], int] = {}
    first_error = ""
    readable = 0
    for bag in bags:
        try:
            with BagReader(bag.path) as reader:
                readable += 1
                for info in reader.topics.values():
                    held[info.name, info.msgtype] = held.get((info.name, info.msgtype), 0) + 1
                reader.topic(settings.command_topic, COMMAND_MSGTYPES)
                reader.topic(settings.encoder_topic, ENCODER_MSGTYPES)
                return
        except BagError as err:
            first_error = first_error or str(err)
    n = len(bags)
    if not readable:
        raise GenBacklashError(
            f"none of the {n} bag{'' if n == 1 else 's'} of {archive} can be read "
            f"(first: {first_error})"
        )
    topics = ", ".join(
        f"{name} ({msgtype}, in {count} bag{'' if count == 1 else 's'})"
        for (name, msgtype), count in sorted(held.items())
    )
    raise GenBacklashError(
        f"no bag of {archive} holds both --command {settings.command_topic} and --encoder "
        f"{settings.encoder_topic} of a supported type; the {readable} readable "
        f"{'bag holds' if readable == 1 else 'bags hold'}: {topics or 'no topics'}"
    )


def inspect_bag(bag: ArchiveBag, settings: FleetSettings) -> BagPlan:
    """The hash, drivetrain and time of ``bag`` (see :mod:`genbacklash_ros.fleet.archive`)."""
    try:
        digest = content_hash(bag.path)
    except OSError as err:
        return BagPlan(
            bag, "", bag.identity.robot, (), bag.identity.time_ns, bag.identity.time_source,
            f"cannot read {bag.relpath}: {err.strerror or err}",
        )  # fmt: skip
    try:
        with BagReader(bag.path) as reader:
            custom = reader.custom_data
    except GenBacklashError:
        custom = None
    robot, joint = metadata_identity(custom)
    robot = robot or bag.identity.robot
    joint = joint or bag.identity.joint
    time_ns, source = bag.identity.time_ns, bag.identity.time_source
    if time_ns is None:
        time_ns = bag_start_ns(bag.path)
        source = "metadata" if time_ns is not None else None
    joints = []
    for request in settings.requests(joint):
        name = request.name or _first_joint(bag.path, settings.encoder_topic)
        joints.append((name, settings.command_index(request)))
    return BagPlan(bag, digest, robot, tuple(joints), time_ns, source)


@dataclass(frozen=True)
class BagResult:
    """One row of the results table: a bag and a joint (see :mod:`genbacklash_ros.fleet.database`
    for the meaning of each column)."""

    bag_hash: str
    joint: str
    settings_key: str
    robot: str
    bag_path: str
    status: str
    reason: str = ""
    recorded_ns: int | None = None
    time_source: str | None = None
    command_index: int = 0
    model: str | None = None
    degree: int | None = None
    c_left: float | None = None
    c_left_std: float | None = None
    c_right: float | None = None
    c_right_std: float | None = None
    gap: float | None = None
    gap_std: float | None = None
    parameters: dict[str, float] | None = None
    parameter_std: dict[str, float] | None = None
    estimate: dict[str, Any] | None = None
    nrmse: float | None = None
    iterations: int | None = None
    converged: bool | None = None
    n_samples: int | None = None
    duration_s: float | None = None
    truncated: bool | None = None
    recorded_s: float | None = None
    diagnose_effects: str | None = None
    diagnose_gap_initial: float | None = None
    diagnose_gap_final: float | None = None
    diagnosis: dict[str, Any] | None = None
    replay_gap: float | None = None
    replay_gap_std: float | None = None
    replay_state: str | None = None
    replay: dict[str, Any] | None = None
    settings: dict[str, Any] | None = None
    software_version: str = __version__
    compute_s: float | None = None

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise GenBacklashError(f"status must be one of {STATUSES}, got {self.status!r}")

    def to_row(self) -> dict[str, Any]:
        """The column -> value mapping (JSON-safe values in the JSON columns)."""
        row = asdict(self)
        for name in ("parameters", "parameter_std", "estimate", "diagnosis", "replay", "settings"):
            row[name] = _json_safe(row[name])
        for name, value in row.items():
            if isinstance(value, float) and not math.isfinite(value):
                row[name] = None  # an uninformed std: unknown, not a number
        return row


def _identify(
    params: NodeParameters, u: np.ndarray, y: np.ndarray, breaks: np.ndarray
) -> IdentificationResult:
    if params.model == "cascade":
        return identify_cascade(u, y, params.degree, params.na, params.nb, breaks=breaks)
    return identify_backlash(u, y, params.degree, breaks=breaks)


def _fit_fields(
    result: IdentificationResult, u: np.ndarray, y: np.ndarray, breaks: np.ndarray
) -> dict[str, Any]:
    model = result.model
    backlash = model.backlash if isinstance(model, Cascade) else model
    cov = parameter_covariance(model, u, y, breaks)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    names = model.parameter_names
    index = {name: i for i, name in enumerate(names)}
    return {
        "model": "cascade" if isinstance(model, Cascade) else "backlash",
        "degree": backlash.degree,
        "c_left": float(backlash.c_left),
        "c_left_std": float(std[index["c_left"]]),
        "c_right": float(backlash.c_right),
        "c_right_std": float(std[index["c_right"]]),
        "gap": float(backlash.c_left + backlash.c_right),
        "gap_std": play_std(model, cov),
        "parameters": dict(zip(names, map(float, model.parameters()), strict=True)),
        "parameter_std": dict(zip(names, map(float, std), strict=True)),
        "estimate": model_to_dict(model),
        "nrmse": float(result.fit.nrmse),
        "iterations": int(result.iterations),
        "converged": bool(result.converged),
        "reason": result.reason,
    }


def truncation_note(read_s: float | None, recorded_s: float | None) -> str:
    """The flag of a cut recording whose readable part was used.

    >>> truncation_note(4.46, 9.9993), truncation_note(4.46, None)
    ('truncated: read 4.5 of 10.0 s', 'truncated: read 4.5 s (the rest is lost)')
    """
    read = "?" if read_s is None else f"{read_s:.1f}"
    if recorded_s is None:
        return f"truncated: read {read} s (the rest is lost)"
    return f"truncated: read {read} of {recorded_s:.1f} s"


def _replay_fields(
    path: Path, settings: FleetSettings, joint: str, command_index: int
) -> dict[str, Any]:
    from genbacklash_ros.bags.replay import replay

    with tempfile.TemporaryDirectory(prefix="genbacklash-fleet-") as tmp:
        result = replay(
            path,
            Path(tmp) / "out",
            command_topic=settings.command_topic,
            encoder_topic=settings.encoder_topic,
            params=settings.params,
            joint=joint,
            command_index=command_index,
        )
    est = result.estimate
    summary = {k: v for k, v in result.to_dict().items() if k != "output"}
    fields: dict[str, Any] = {"replay": summary, "replay_state": est.state.value}
    if est.model is not None:
        play, play_std = est.play()
        fields["replay_gap"] = play
        fields["replay_gap_std"] = play_std
    if result.error:
        summary["error"] = result.error
    return fields


def _analyse_joint(
    plan: BagPlan, settings: FleetSettings, joint: str, command_index: int
) -> dict[str, Any]:
    """The measured columns of one joint (raises for a bag or data that cannot be used)."""
    series = read_aligned(
        plan.bag.path,
        settings.command_topic,
        settings.encoder_topic,
        joint=joint,
        command_index=command_index,
        keep_readable=True,  # a cut recording: its readable part, flagged (as replay keeps it)
    )
    out: dict[str, Any] = {
        "n_samples": int(series.u.size),
        "duration_s": float((series.t[-1] - series.t[0]) / 1e9) if series.t.size else 0.0,
        "truncated": bool(series.damage),
    }
    flag = ""
    if series.damage:
        recorded = recorded_duration_ns(plan.bag.path)
        out["recorded_s"] = None if recorded is None else recorded / 1e9
        flag = f"{truncation_note(out['duration_s'], out['recorded_s'])} ({series.damage})"
    try:
        out.update(_measure(plan, settings, joint, command_index, series))
    except Exception as err:  # the row keeps what was read, and the flag
        out["status"], out["reason"] = _status_of(err)
    if flag:
        out["reason"] = f"{flag}; {out['reason']}"
    return out


def _measure(
    plan: BagPlan,
    settings: FleetSettings,
    joint: str,
    command_index: int,
    series: AlignedSeries,
) -> dict[str, Any]:
    """Identify, diagnose and replay one joint's aligned samples (raises for data that
    cannot be used)."""
    out: dict[str, Any] = {}
    result = _identify(settings.params, series.u, series.y, series.breaks)
    out.update(_fit_fields(result, series.u, series.y, series.breaks))
    out["status"] = "ok" if result.converged else "not_converged"
    if result.converged and not out["nrmse"] <= settings.max_nrmse:
        out["status"] = "poor_fit"
        out["reason"] = (
            f"free-run NRMSE {out['nrmse']:.3g} is above max_nrmse {settings.max_nrmse:g}: "
            f"the estimate is not trusted; {out['reason']}"
        )
    if settings.diagnose:
        start = None
        if settings.diagnose_from_params:
            s = settings.params.structure()
            start = StartStructure(s.degree, s.na, s.nb)
        try:
            found = diagnose(
                series.u,
                series.y,
                start=start,
                settings=DiagnoseSettings(validation=settings.validation),
                breaks=series.breaks,
            )
        except GenBacklashError as err:
            out["reason"] = f"{out['reason']}; diagnose: {err}".lstrip("; ")
        else:
            out["diagnosis"] = found.to_dict()
            out["diagnose_effects"] = ",".join(step.effect for step in found.steps)
            out["diagnose_gap_initial"] = float(found.gap_initial)
            out["diagnose_gap_final"] = float(found.gap_final)
    if settings.replay:
        out.update(_replay_fields(plan.bag.path, settings, joint, command_index))
    return out


def _status_of(err: Exception) -> tuple[str, str]:
    if isinstance(err, NotEnoughExcitationError):
        return "no_motion", str(err)
    if isinstance(err, BagError):
        return "unreadable", str(err)
    if isinstance(err, GenBacklashError):
        return "failed", str(err)
    return "failed", f"{type(err).__name__}: {err}"


def analyse_bag(plan: BagPlan, settings: FleetSettings) -> tuple[BagResult, ...]:
    """One :class:`BagResult` per joint of ``plan`` (see the module notes); never raises for
    a bad bag."""
    common: dict[str, Any] = {
        "bag_hash": plan.bag_hash,
        "robot": plan.robot,
        "bag_path": plan.bag.relpath,
        "recorded_ns": plan.recorded_ns,
        "time_source": plan.time_source,
    }
    if plan.reason:
        return (
            BagResult(
                joint="",
                settings_key=settings.key("", settings.params.command_index),
                status="unreadable",
                reason=plan.reason,
                settings=settings.to_dict("", settings.params.command_index),
                **common,
            ),
        )
    results = []
    for joint, index in plan.joints:
        started = time.perf_counter()
        try:
            fields = _analyse_joint(plan, settings, joint, index)
        except Exception as err:  # a bad bag is a row, never a lost archive
            status, reason = _status_of(err)
            fields = {"status": status, "reason": reason}
        results.append(
            BagResult(
                joint=joint,
                settings_key=settings.key(joint, index),
                command_index=index,
                settings=settings.to_dict(joint, index),
                compute_s=time.perf_counter() - started,
                **common,
                **fields,
            )
        )
    return tuple(results)
