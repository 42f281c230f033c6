"""Checkpoints: exact round trip, atomic writes that survive a crash, corrupt files, warm start."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from genbacklash_core import (
    Estimate,
    EstimatorState,
    RecursiveIdentifier,
    Structure,
    WindowedIdentifier,
    paper_example,
)
from genbacklash_core.measured import HeldHarm, OfflineBaseline
from genbacklash_ros.node import checkpoint as ckpt
from genbacklash_ros.node.checkpoint import (
    CHECKPOINT_VERSION,
    Checkpoint,
    CheckpointError,
    checkpoint_from_dict,
    checkpoint_to_dict,
    load_checkpoint,
    save_checkpoint,
    warm_start,
)
from genbacklash_ros.node.parameters import NodeParameters


def converged(sign: float = 1.0) -> Estimate:
    number = 1 if sign > 0 else 2
    truth = paper_example(number).model
    rng = np.random.default_rng(3)
    a = rng.normal(size=(8, 8)) * 1e-3
    return Estimate(
        Structure(3, sign=sign),
        truth.parameters(),
        a @ a.T,
        0.0213,
        0.61,
        EstimatorState.CONVERGED,
        0.87,
        12_345,
        "settled; relative std 0.004",
    )


def test_round_trip_is_exact(tmp_path: Path) -> None:
    est = converged()
    path = save_checkpoint(tmp_path / "c.json", est, time_ns=123_456_789_012)
    back = load_checkpoint(path)
    assert back.time_ns == 123_456_789_012 and back.version == CHECKPOINT_VERSION
    got = back.estimate
    assert got.structure == est.structure
    assert np.array_equal(got.parameters, est.parameters)
    assert np.array_equal(got.covariance, est.covariance)
    assert (got.residual, got.excitation, got.confidence) == (
        est.residual,
        est.excitation,
        est.confidence,
    )
    assert (got.state, got.samples, got.reason) == (est.state, est.samples, est.reason)


def test_round_trip_of_an_estimate_without_parameters(tmp_path: Path) -> None:
    est = Estimate.empty(Structure(2, 1, 1, -1.0), samples=7)
    back = load_checkpoint(save_checkpoint(tmp_path / "c.json", est, 5)).estimate
    assert back.structure == est.structure and back.samples == 7
    assert np.all(np.isnan(back.parameters)) and math.isnan(back.residual)
    data = json.loads((tmp_path / "c.json").read_text())
    assert data["parameters"] == [None] * est.structure.n_parameters  # strict JSON, no NaN


def test_file_layout(tmp_path: Path) -> None:
    save_checkpoint(tmp_path / "c.json", converged(), 1)
    data = json.loads((tmp_path / "c.json").read_text())
    assert data["format"] == "genbacklash-checkpoint" and data["version"] == CHECKPOINT_VERSION
    assert data["names"][3] == "c_left" and data["structure"]["degree"] == 3
    assert checkpoint_from_dict(data).estimate.state is EstimatorState.CONVERGED
    assert checkpoint_from_dict(checkpoint_to_dict(Checkpoint(converged(), 9))).time_ns == 9


def test_the_offline_baseline_round_trips(tmp_path: Path) -> None:
    base = OfflineBaseline(0.0361234567890123, 39.99893)
    path = save_checkpoint(tmp_path / "c.json", Checkpoint(converged(), 7, baseline=base))
    back = load_checkpoint(path)
    assert back.baseline == base  # exact: JSON keeps every digit of a float
    assert json.loads(path.read_text())["baseline"] == {"rms": base.rms, "seconds": base.seconds}
    taken = warm_start(NodeParameters(checkpoint_file=str(path)))
    assert taken.baseline == base and "offline baseline" in taken.note


def test_a_checkpoint_without_a_baseline_still_loads(tmp_path: Path) -> None:
    data = checkpoint_to_dict(Checkpoint(converged(), 3))
    assert "baseline" not in data  # the old layout, unchanged
    assert checkpoint_from_dict(data).baseline is None
    path = save_checkpoint(tmp_path / "c.json", converged(), 3)
    assert warm_start(NodeParameters(checkpoint_file=str(path))).baseline is None


@pytest.mark.parametrize(
    ("baseline", "match"),
    [
        (0.03, "baseline must be an object"),
        ({"rms": 0.03}, "'seconds' is missing"),
        ({"rms": -0.03, "seconds": 4.0}, "baseline: rms must be a finite number > 0"),
        ({"rms": "x", "seconds": 4.0}, "baseline: rms must be a number"),
    ],
)
def test_a_corrupt_baseline_is_reported(baseline: object, match: str) -> None:
    data = checkpoint_to_dict(Checkpoint(converged(), 3))
    data["baseline"] = baseline
    with pytest.raises(CheckpointError, match=match):
        checkpoint_from_dict(data)


def test_a_verdict_of_harm_round_trips_and_the_start_says_so(tmp_path: Path) -> None:
    harm = HeldHarm(0.056396459711464, 1.1951608204238333, 5.888067188999997)
    path = save_checkpoint(tmp_path / "c.json", Checkpoint(converged(), 7, harm=harm))
    back = load_checkpoint(path)
    assert back.harm == harm and back.baseline is None  # exact
    data = json.loads(path.read_text())
    assert data["harm"] == {"play": harm.play, "ratio": harm.ratio, "held": harm.held}
    assert "baseline" not in data
    taken = warm_start(NodeParameters(checkpoint_file=str(path)))
    assert taken.harm == harm
    assert "tracking worse than without (120 % of the error)" in taken.note
    assert "harm" not in checkpoint_to_dict(Checkpoint(converged(), 3))  # the old layout
    assert warm_start(NodeParameters(checkpoint_file=str(save_checkpoint(
        tmp_path / "d.json", converged(), 3)))).harm is None  # fmt: skip


@pytest.mark.parametrize(
    ("harm", "match"),
    [
        ([0.04, 1.2, 0.0], "harm must be an object"),
        ({"play": 0.04, "ratio": 1.2}, "'held' is missing"),
        ({"play": None, "ratio": 1.2, "held": 0.0}, "harm: play must be a number"),
        ({"play": 0.04, "ratio": -1.0, "held": 0.0}, "harm: ratio must be > 0"),
    ],
)
def test_a_corrupt_verdict_of_harm_is_reported(harm: object, match: str) -> None:
    data = checkpoint_to_dict(Checkpoint(converged(), 3))
    data["harm"] = harm
    with pytest.raises(CheckpointError, match=match):
        checkpoint_from_dict(data)


# --------------------------------------------------------------------------- atomicity


def leftovers(directory: Path) -> list[str]:
    return sorted(p.name for p in directory.iterdir() if p.name.endswith(".tmp"))


def test_a_failure_mid_write_keeps_the_old_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "c.json"
    save_checkpoint(path, converged(), 1)
    before = path.read_bytes()

    def broken_fsync(fd: int) -> None:
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(ckpt.os, "fsync", broken_fsync)
    with pytest.raises(CheckpointError, match=r"cannot write checkpoint .*No space left"):
        save_checkpoint(path, Estimate.empty(Structure(3)), 2)
    assert path.read_bytes() == before
    assert load_checkpoint(path).time_ns == 1
    assert leftovers(tmp_path) == []  # the temporary file is cleaned up


def test_an_interrupt_before_the_rename_keeps_the_old_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "c.json"
    save_checkpoint(path, converged(), 1)

    def interrupted(src: object, dst: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(ckpt.os, "replace", interrupted)
    with pytest.raises(KeyboardInterrupt):
        save_checkpoint(path, converged(), 2)
    assert load_checkpoint(path).time_ns == 1 and leftovers(tmp_path) == []


def test_a_process_killed_mid_write_leaves_the_old_file(tmp_path: Path) -> None:
    """A real crash: the child dies (os._exit) after writing half of the new file."""
    path = tmp_path / "c.json"
    save_checkpoint(path, converged(), 1)
    before = path.read_bytes()
    child = textwrap.dedent(
        f"""
        import os
        from genbacklash_ros.node import checkpoint as ckpt
        real_fdopen = os.fdopen

        class Dying:
            def __init__(self, handle):
                self.handle = handle
            def __enter__(self):
                return self
            def __exit__(self, *exc):
                return False
            def write(self, text):
                self.handle.write(text[: len(text) // 2])
                self.handle.flush()
                os._exit(3)

        ckpt.os.fdopen = lambda fd, *a, **k: Dying(real_fdopen(fd, *a, **k))
        est = ckpt.load_checkpoint({str(path)!r}).estimate
        ckpt.save_checkpoint({str(path)!r}, est, 2)
        """
    )
    done = subprocess.run([sys.executable, "-c", child], capture_output=True, timeout=60)
    assert done.returncode == 3, done.stderr.decode()
    assert path.read_bytes() == before
    assert load_checkpoint(path).time_ns == 1
    assert len(leftovers(tmp_path)) == 1  # the half-written temporary file, never the target


def test_unwritable_directory_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="cannot write checkpoint"):
        save_checkpoint(tmp_path / "missing_dir" / "c.json", converged(), 1)


# --------------------------------------------------------------------------- corrupt files


def corrupt(data: dict[str, Any], **changes: Any) -> dict[str, Any]:
    out = dict(data)
    out.update(changes)
    return out


GOOD = checkpoint_to_dict(Checkpoint(converged(), 1))


@pytest.mark.parametrize(
    ("content", "match"),
    [
        ('{"format": "genbacklash-checkpoint", "vers', r"not valid JSON .* at line 1"),
        ("[]", "expected a JSON object, got list"),
        (json.dumps(corrupt(GOOD, format="other")), "not a genbacklash checkpoint"),
        (json.dumps(corrupt(GOOD, version=99)), "checkpoint version 99 is not supported"),
        (
            json.dumps({k: v for k, v in GOOD.items() if k != "covariance"}),
            "'covariance' is missing",
        ),
        (json.dumps(corrupt(GOOD, covariance=[[1.0]])), "covariance must be 8 rows of 8 numbers"),
        (json.dumps(corrupt(GOOD, parameters=[1.0, 2.0])), r"parameters must have shape \(8,\)"),
        (json.dumps(corrupt(GOOD, parameters=["a"] * 8)), r"parameters\[0\] must be a number"),
        (json.dumps(corrupt(GOOD, names=["x"] * 8)), "do not match the structure"),
        (json.dumps(corrupt(GOOD, state="happy")), "state must be one of"),
        (json.dumps(corrupt(GOOD, confidence=3.0)), r"confidence must lie in \[0, 1\]"),
        (json.dumps(corrupt(GOOD, samples=-1)), "samples must be a whole number"),
        (json.dumps(corrupt(GOOD, time_ns="soon")), "time_ns must be whole nanoseconds"),
        (json.dumps(corrupt(GOOD, structure={"degree": 0, "na": 0, "nb": 0, "sign": 1})), "degree"),
    ],
)
def test_corrupt_files_are_reported(tmp_path: Path, content: str, match: str) -> None:
    path = tmp_path / "c.json"
    path.write_text(content)
    with pytest.raises(CheckpointError, match=f"checkpoint .*c.json is corrupt: .*{match}"):
        load_checkpoint(path)


def test_unreadable_files(tmp_path: Path) -> None:
    with pytest.raises(CheckpointError, match="does not exist"):
        load_checkpoint(tmp_path / "absent.json")
    (tmp_path / "bin.json").write_bytes(b"\xff\xfe\x00")
    with pytest.raises(CheckpointError, match="not UTF-8"):
        load_checkpoint(tmp_path / "bin.json")


# --------------------------------------------------------------------------- warm start


def test_warm_start_without_a_file_is_cold_and_quiet(tmp_path: Path) -> None:
    start = warm_start(NodeParameters(checkpoint_file=str(tmp_path / "none.json")))
    assert start.prior is None and start.note == "" and not start.problem
    assert isinstance(start.identifier, WindowedIdentifier)
    assert warm_start(NodeParameters()).prior is None


def test_warm_start_from_a_checkpoint(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    est = converged(sign=-1.0)
    save_checkpoint(path, est, 2_000_000_000)
    params = NodeParameters(checkpoint_file=str(path), method="recursive")
    start = warm_start(params)
    assert isinstance(start.identifier, RecursiveIdentifier)
    assert start.identifier.structure.sign == -1.0  # the sense comes from the checkpoint
    assert start.prior is not None and start.prior.model == est.model
    assert start.prior.samples == 0 and start.prior.confidence == est.confidence
    assert "from checkpoint" in start.prior.reason and "2.000 s" in start.prior.reason
    assert not start.problem and "warm start" in start.note


@pytest.mark.parametrize(
    ("params", "content", "match"),
    [
        ({}, "{", "is corrupt"),
        ({"degree": 2}, None, "holds degree 3, na 0, nb 0; the parameters ask for degree 2"),
        ({"model": "cascade"}, None, "ask for degree 3, na 2, nb 2"),
    ],
)
def test_warm_start_falls_back_to_cold_with_a_note(
    tmp_path: Path, params: dict[str, Any], content: str | None, match: str
) -> None:
    path = tmp_path / "c.json"
    if content is None:
        save_checkpoint(path, converged(), 1)
    else:
        path.write_text(content)
    start = warm_start(NodeParameters(checkpoint_file=str(path), **params))
    assert start.prior is None and start.problem
    assert match in start.note and start.note.endswith("starting cold")


def test_warm_start_ignores_a_checkpoint_without_model(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    save_checkpoint(path, Estimate.empty(Structure(3)), 1)
    start = warm_start(NodeParameters(), path)
    assert start.prior is None and "holds no valid model" in start.note


def test_no_temporary_files_in_normal_use(tmp_path: Path) -> None:
    for k in range(3):
        save_checkpoint(tmp_path / "c.json", converged(), k)
    assert sorted(os.listdir(tmp_path)) == ["c.json"]


@pytest.mark.parametrize("method", ["windowed", "recursive"])
def test_warm_start_seeds_the_identifier(tmp_path: Path, method: str) -> None:
    path = tmp_path / "c.json"
    est = converged()
    save_checkpoint(path, est, 3_000_000_000)
    start = warm_start(NodeParameters(checkpoint_file=str(path), method=method))
    assert start.seeded and "the identifier continues from its estimate" in start.note
    own = start.identifier.estimate
    assert own.state is EstimatorState.CONVERGED and start.identifier.from_seed
    assert np.allclose(own.parameters, est.parameters, rtol=1e-12, atol=1e-12)
    assert own.samples == est.samples  # the count goes on


def test_warm_start_without_a_usable_covariance_lets_the_prior_stand_in(tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    base = converged()
    est = Estimate(
        base.structure, base.parameters, np.zeros((8, 8)), 0.02, 0.6, "converged", 0.9, 10
    )
    save_checkpoint(path, est, 1)
    start = warm_start(NodeParameters(checkpoint_file=str(path)))
    assert not start.seeded and not start.problem
    assert start.prior is not None and start.prior.model == est.model
    assert "stands in until the identifier converges" in start.note
    assert start.identifier.estimate.state is EstimatorState.WARMING_UP
