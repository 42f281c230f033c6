"""Checkpoints of the online estimate: an atomic JSON file and a warm start from it.

A checkpoint holds one :class:`~genbacklash_core.Estimate` (structure, parameters,
covariance, residual, excitation, state, confidence, samples, reason) and the data time it
was taken at, under a format ``version``; optionally the drivetrain's tracking without
compensation as the measured tracking judge measures it
(:class:`~genbacklash_core.measured.OfflineBaseline`, the field ``baseline``: ``{"rms": rad,
"seconds": s}``), which a start from the file takes as the judge's baseline
(:func:`warm_start`). ``identify``/``replay --checkpoint`` store the record's (on a record
without compensation); the node's own checkpoints, with ``compensation_in_loop`` and once its
judge has measured compensation clearly helping, store the one the judge measured live (at least
``min_time`` of it) or else carry forward the one it started from, and otherwise none
(:mod:`genbacklash_ros.node.pipeline`). A node whose judge holds compensation off because it
measured it tracking worse than without stores that verdict too
(:class:`~genbacklash_core.measured.HeldHarm`, the field ``harm``: ``{"play": rad, "ratio": q,
"held": s}``), which the next start holds: the model stays off until a new one or the judge's
``retry``, as in the running node. A file without these fields loads as before.
:func:`save_checkpoint` writes it atomically: a temporary file in the same directory is
written, flushed and fsync'ed, then renamed over the target (``os.replace``), and the
directory is fsync'ed; a crash at any point leaves either the old file or the new one, never
a half-written one (a process killed while writing leaves its temporary file behind:
:func:`warm_start`, run when the node starts again, removes it).
:func:`load_checkpoint` validates everything and raises :class:`CheckpointError` with the
reason on a corrupt file.

:func:`warm_start` turns a checkpoint into a start for the node: the identifier is created
with the checkpoint's branch sense and *seeded* with the checkpoint's estimate
(:meth:`~genbacklash_core.WindowedIdentifier.seed`,
:meth:`~genbacklash_core.RecursiveIdentifier.seed`): it continues from the saved parameters
and their uncertainty instead of a cold start, so the estimate after a restart is the saved
one and goes on from there without a warm-up. The checkpoint's estimate is also returned as
the *prior*, which the pipeline publishes and compensates with should the identifier not take
the seed (then until it has an estimate of its own).

Examples
--------
>>> import tempfile, numpy as np
>>> from genbacklash_core import Estimate, Structure, paper_example
>>> truth = paper_example(1).model
>>> est = Estimate(Structure(3), truth.parameters(), np.eye(8) * 1e-4, 0.02, 0.6,
...                "converged", 0.9, 500, "settled")
>>> with tempfile.TemporaryDirectory() as tmp:
...     path = save_checkpoint(f"{tmp}/estimate.json", est, time_ns=1_500_000_000)
...     back = load_checkpoint(path)
>>> back.time_ns, back.estimate.state.value, back.estimate.model == truth
(1500000000, 'converged', True)
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from genbacklash_core import Estimate, GenBacklashError, OnlineIdentifier, Structure
from genbacklash_core.measured import HeldHarm, OfflineBaseline
from genbacklash_ros.node.parameters import NodeParameters

__all__ = [
    "CHECKPOINT_VERSION",
    "Checkpoint",
    "CheckpointError",
    "WarmStart",
    "checkpoint_from_dict",
    "checkpoint_to_dict",
    "load_checkpoint",
    "remove_stale_temporaries",
    "save_checkpoint",
    "warm_start",
]

CHECKPOINT_VERSION = 1
_FORMAT = "genbacklash-checkpoint"


class CheckpointError(GenBacklashError):
    """A checkpoint file is missing, unreadable or corrupt (the message says which)."""


@dataclass(frozen=True)
class Checkpoint:
    """A saved estimate and the data time (integer nanoseconds) it was taken at.

    ``baseline``: the tracking without compensation, measured on the record the estimate
    was identified on (``identify``, ``replay``) or live by the node that wrote the file
    (None: not measured, or the record had compensation in it). ``harm``: the node's
    verdict that compensation with this model tracked worse than without, held when the file
    was written (None: no such verdict held).
    """

    estimate: Estimate
    time_ns: int
    version: int = CHECKPOINT_VERSION
    baseline: OfflineBaseline | None = None
    harm: HeldHarm | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.estimate, Estimate):
            raise CheckpointError(f"estimate must be an Estimate, got {self.estimate!r}")
        if isinstance(self.time_ns, bool) or not isinstance(self.time_ns, int):
            raise CheckpointError(f"time_ns must be whole nanoseconds, got {self.time_ns!r}")
        if self.version != CHECKPOINT_VERSION:
            raise CheckpointError(
                f"checkpoint version {self.version!r} is not supported (this is version "
                f"{CHECKPOINT_VERSION})"
            )
        if self.baseline is not None and not isinstance(self.baseline, OfflineBaseline):
            raise CheckpointError(f"baseline must be an OfflineBaseline, got {self.baseline!r}")
        if self.harm is not None and not isinstance(self.harm, HeldHarm):
            raise CheckpointError(f"harm must be a HeldHarm, got {self.harm!r}")

    def mismatch(self, structure: Structure) -> str | None:
        """Why the checkpoint cannot warm-start ``structure`` (degree, na, nb), or None."""
        saved = self.estimate.structure
        if (saved.degree, saved.na, saved.nb) != (structure.degree, structure.na, structure.nb):
            return (
                f"the checkpoint holds degree {saved.degree}, na {saved.na}, nb {saved.nb}; "
                f"the parameters ask for degree {structure.degree}, na {structure.na}, "
                f"nb {structure.nb}"
            )
        return None


# --------------------------------------------------------------------------- JSON form


def _clean(values: list[Any]) -> list[Any]:
    """NaN/inf -> None, recursively (JSON has no NaN)."""
    return [_clean(v) if isinstance(v, list) else (v if math.isfinite(v) else None) for v in values]


def _number(value: object, what: str) -> float:
    if value is None:
        return math.nan
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise CheckpointError(f"{what} must be a number or null, got {value!r}")
    return float(value)


def checkpoint_to_dict(checkpoint: Checkpoint) -> dict[str, Any]:
    """The JSON-ready dict of a checkpoint (NaN becomes null)."""
    est = checkpoint.estimate
    s = est.structure
    out: dict[str, Any] = {
        "format": _FORMAT,
        "version": checkpoint.version,
        "time_ns": checkpoint.time_ns,
        "structure": {"degree": s.degree, "na": s.na, "nb": s.nb, "sign": s.sign},
        "names": list(est.names),
        "parameters": _clean(est.parameters.tolist()),
        "covariance": _clean(est.covariance.tolist()),
        "residual": est.residual if math.isfinite(est.residual) else None,
        "excitation": est.excitation,
        "state": est.state.value,
        "confidence": est.confidence,
        "samples": est.samples,
        "reason": est.reason,
    }
    if checkpoint.baseline is not None:
        out["baseline"] = {"rms": checkpoint.baseline.rms, "seconds": checkpoint.baseline.seconds}
    if checkpoint.harm is not None:
        harm = checkpoint.harm
        out["harm"] = {"play": harm.play, "ratio": harm.ratio, "held": harm.held}
    return out


def _baseline(data: dict[str, Any]) -> OfflineBaseline | None:
    """The optional ``baseline`` field (absent or null: None)."""
    raw = data.get("baseline")
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise CheckpointError("baseline must be an object with rms and seconds")
    try:
        return OfflineBaseline(_field(raw, "rms"), _field(raw, "seconds"))
    except GenBacklashError as err:
        raise CheckpointError(f"baseline: {err}") from err


def _harm(data: dict[str, Any]) -> HeldHarm | None:
    """The optional ``harm`` field (absent or null: None)."""
    raw = data.get("harm")
    if raw is None:
        return None
    if not isinstance(raw, dict):
        raise CheckpointError("harm must be an object with play, ratio and held")
    try:
        return HeldHarm(_field(raw, "play"), _field(raw, "ratio"), _field(raw, "held"))
    except GenBacklashError as err:
        raise CheckpointError(f"harm: {err}") from err


def _field(data: dict[str, Any], key: str) -> Any:
    if key not in data:
        raise CheckpointError(f"the field {key!r} is missing")
    return data[key]


def _numbers(values: object, what: str) -> list[float]:
    if not isinstance(values, list):
        raise CheckpointError(f"{what} must be a list of numbers")
    return [_number(v, f"{what}[{k}]") for k, v in enumerate(values)]


def checkpoint_from_dict(data: object) -> Checkpoint:
    """A validated checkpoint from its JSON dict; :class:`CheckpointError` says what is wrong."""
    if not isinstance(data, dict):
        raise CheckpointError(f"expected a JSON object, got {type(data).__name__}")
    if data.get("format") != _FORMAT:
        raise CheckpointError(f"not a genbacklash checkpoint (format {data.get('format')!r})")
    version = _field(data, "version")
    if version != CHECKPOINT_VERSION:
        raise CheckpointError(
            f"checkpoint version {version!r} is not supported (this is version "
            f"{CHECKPOINT_VERSION})"
        )
    try:
        raw = _field(data, "structure")
        if not isinstance(raw, dict):
            raise CheckpointError("structure must be an object")
        structure = Structure(
            _field(raw, "degree"), _field(raw, "na"), _field(raw, "nb"), _field(raw, "sign")
        )
        names = _field(data, "names")
        if names != list(structure.names()):
            raise CheckpointError(
                f"the parameter names {names!r} do not match the structure "
                f"({', '.join(structure.names())})"
            )
        size = structure.n_parameters
        parameters = _numbers(_field(data, "parameters"), "parameters")
        rows = _field(data, "covariance")
        if not isinstance(rows, list) or len(rows) != size:
            raise CheckpointError(f"covariance must be {size} rows of {size} numbers")
        covariance = [_numbers(row, f"covariance[{k}]") for k, row in enumerate(rows)]
        if any(len(row) != size for row in covariance):
            raise CheckpointError(f"covariance must be {size} rows of {size} numbers")
        reason = _field(data, "reason")
        if not isinstance(reason, str):
            raise CheckpointError("reason must be a string")
        time_ns = _field(data, "time_ns")
        estimate = Estimate(
            structure,
            np.array(parameters),
            np.array(covariance).reshape(size, size),
            _number(_field(data, "residual"), "residual"),
            _number(_field(data, "excitation"), "excitation"),
            _field(data, "state"),
            _number(_field(data, "confidence"), "confidence"),
            _field(data, "samples"),
            reason,
        )
        return Checkpoint(estimate, time_ns, version, _baseline(data), _harm(data))
    except CheckpointError:
        raise
    except (GenBacklashError, TypeError) as err:
        raise CheckpointError(str(err)) from err


# --------------------------------------------------------------------------- files


def _fsync_directory(directory: Path) -> None:
    """Make a rename durable (POSIX); a no-op where directories cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_atomic(path: str | Path, text: str) -> Path:
    """Write ``text`` to ``path`` atomically: temp file, flush, fsync, ``os.replace``.

    On any error the temporary file is removed and the old ``path`` is left as it was.
    """
    target = Path(path)
    directory = target.parent
    fd, temp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            handle.write(text)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(temp_name, target)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temp_name)
        raise
    _fsync_directory(directory)
    return target


def remove_stale_temporaries(path: str | Path) -> int:
    """Remove the temporary files a writer of ``path`` killed mid-write left; how many.

    They are named ``.<name>.<random>.tmp`` next to ``path`` (see :func:`write_atomic`).
    Call it when no other process writes ``path``, e.g. when the node starts.
    """
    target = Path(path)
    removed = 0
    try:
        leftovers = list(target.parent.glob(f".{target.name}.*.tmp"))
    except OSError:
        return 0
    for leftover in leftovers:
        with contextlib.suppress(OSError):
            leftover.unlink()
            removed += 1
    return removed


def save_checkpoint(
    path: str | Path, estimate: Estimate | Checkpoint, time_ns: int | None = None
) -> Path:
    """Save ``estimate`` (taken at data time ``time_ns``) to ``path`` atomically.

    Pass an :class:`~genbacklash_core.Estimate` with ``time_ns``, or a :class:`Checkpoint`.
    Raises :class:`CheckpointError` when the file cannot be written (the old one survives).
    """
    if isinstance(estimate, Checkpoint):
        checkpoint = estimate
    else:
        checkpoint = Checkpoint(estimate, 0 if time_ns is None else time_ns)
    text = json.dumps(checkpoint_to_dict(checkpoint), indent=1, allow_nan=False)
    target = Path(path)
    try:
        return write_atomic(target, text + "\n")
    except OSError as err:
        raise CheckpointError(f"cannot write checkpoint {target}: {err.strerror or err}") from err


def load_checkpoint(path: str | Path) -> Checkpoint:
    """Read and validate a checkpoint; :class:`CheckpointError` names the file and the fault."""
    file = Path(path)
    try:
        text = file.read_text(encoding="utf-8")
    except FileNotFoundError as err:
        raise CheckpointError(f"checkpoint {file} does not exist") from err
    except OSError as err:
        raise CheckpointError(f"cannot read checkpoint {file}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise CheckpointError(f"checkpoint {file} is corrupt: not UTF-8 text") from err
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise CheckpointError(
            f"checkpoint {file} is corrupt: not valid JSON ({err.msg} at line {err.lineno})"
        ) from err
    try:
        return checkpoint_from_dict(data)
    except CheckpointError as err:
        raise CheckpointError(f"checkpoint {file} is corrupt: {err}") from err


# --------------------------------------------------------------------------- warm start


@dataclass(frozen=True)
class WarmStart:
    """What :func:`warm_start` makes of a checkpoint file.

    Attributes
    ----------
    identifier : OnlineIdentifier
        A fresh identifier; with the checkpoint's branch sense and seeded with its estimate
        when one was used (see ``seeded``).
    prior : Estimate or None
        The checkpoint's estimate (samples reset to 0), to compensate and publish with until
        the identifier has one of its own (at once when it was seeded); None when there is
        no usable checkpoint.
    note : str
        What happened, for the log and the diagnostics: ``""`` when no checkpoint file is
        configured or it does not exist yet.
    problem : bool
        True when a checkpoint exists but could not be used (corrupt, other structure).
    seeded : bool
        True when the identifier continues from the checkpoint's estimate.
    baseline : OfflineBaseline or None
        The checkpoint's tracking without compensation, measured offline, for the measured
        tracking judge (:meth:`~genbacklash_core.measured.TrackingJudge.start_from`); None
        without a usable checkpoint or when it holds none.
    harm : HeldHarm or None
        The verdict of harm the node that wrote the checkpoint held, for the judge to hold
        (:meth:`~genbacklash_core.measured.TrackingJudge.hold`); None without a usable
        checkpoint or when it holds none.
    """

    identifier: OnlineIdentifier
    prior: Estimate | None
    note: str = ""
    problem: bool = False
    seeded: bool = False
    baseline: OfflineBaseline | None = None
    harm: HeldHarm | None = None


def warm_start(params: NodeParameters, path: str | Path | None = None) -> WarmStart:
    """An identifier for ``params``, warm-started from the checkpoint at ``path``.

    ``path`` defaults to ``params.checkpoint_file``. Temporary files a killed writer left
    next to it are removed (:func:`remove_stale_temporaries`). A missing file starts cold without a
    note; a corrupt file, one of another structure, or one without parameters starts cold
    with a note saying why (never an exception: a node must still come up). A checkpoint
    whose estimate cannot seed the identifier (no finite covariance or residual) still
    stands in as the prior until the identifier converges; the note says so.
    """
    file = params.checkpoint_file if path is None else str(path)
    if file:
        remove_stale_temporaries(file)  # of a node killed while it wrote a checkpoint
    if not file or not Path(file).exists():
        return WarmStart(params.make_identifier(), None)
    try:
        checkpoint = load_checkpoint(file)
    except CheckpointError as err:
        return WarmStart(params.make_identifier(), None, f"{err}; starting cold", True)
    mismatch = checkpoint.mismatch(params.structure())
    if mismatch is not None:
        note = f"checkpoint {file} not used: {mismatch}; starting cold"
        return WarmStart(params.make_identifier(), None, note, True)
    estimate = checkpoint.estimate
    if estimate.model is None:
        note = f"checkpoint {file} holds no valid model; starting cold"
        return WarmStart(params.make_identifier(), None, note, True)
    identifier = params.make_identifier(sign=estimate.structure.sign)
    saved_at = f"saved at data time {checkpoint.time_ns / 1e9:.3f} s"
    try:
        identifier.seed(estimate)
    except GenBacklashError as err:
        seeded = False
        how = f"{saved_at}; its estimate stands in until the identifier converges: {err}"
    else:
        seeded = True
        how = f"{saved_at}; the identifier continues from its estimate"
    if checkpoint.baseline is not None:
        how += (
            f"; its offline baseline ({1e3 * checkpoint.baseline.rms:.3g} mrad rms without "
            "compensation) lets compensation start once the guard has judged the model on this "
            "machine's samples, not after a 3 s baseline; the live one replaces it"
        )
    if checkpoint.harm is not None:
        how += (
            f"; compensation with its model was measured tracking worse than without "
            f"({100 * checkpoint.harm.ratio:.0f} % of the error) and stays off until a new "
            f"model or the judge's retry ({checkpoint.harm.held:.0f} s of it held so far)"
        )
    prior = Estimate(
        estimate.structure,
        estimate.parameters,
        estimate.covariance,
        estimate.residual,
        estimate.excitation,
        estimate.state,
        estimate.confidence,
        0,
        f"from checkpoint {file} ({saved_at}): {estimate.reason}",
    )
    note = f"warm start from checkpoint {file} ({how})"
    return WarmStart(
        identifier,
        prior,
        note,
        seeded=seeded,
        baseline=checkpoint.baseline,
        harm=checkpoint.harm,
    )
