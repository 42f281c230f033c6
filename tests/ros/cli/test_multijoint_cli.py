"""Several joints from one bag: ``replay``, ``identify`` and ``diagnose`` with ``--joint a
--joint b`` (or ``--joint a,b``) and one ``--command-index`` per joint.

The bag: a simulated three-joint arm (:func:`genbacklash_core.scenarios.arm_records`, each joint
its own motion and its own backlash) as one four-element Float64MultiArray command (element 1
no joint's) and one three-joint JointState (:func:`genbacklash_ros.bags.simbags.write_arm_bag`).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import GeneralBacklash
from genbacklash_core.scenarios import OPERATION_BACKLASH, OperationSettings, arm_records, worn
from genbacklash_ros.bags.simbags import write_arm_bag
from genbacklash_ros.cli.main import main

NAMES = ("shoulder", "elbow", "wrist")
INDICES = (0, 2, 3)
MODELS = (
    OPERATION_BACKLASH,
    worn(OPERATION_BACKLASH, 1.6),
    GeneralBacklash((1.0, 0.02, -0.01), 0.03, (1.0, 0.02, -0.01), 0.025),
)
TOPICS = ["--command", "/command", "--encoder", "/encoder"]


@pytest.fixture(scope="module")
def arm_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("arm") / "arm_bag"
    records = arm_records(MODELS, OperationSettings(duration=12.0), seed=5)
    write_arm_bag(path, records, NAMES, INDICES, 4)
    return path


def _params(entry: dict[str, float | list[float]]) -> np.ndarray:
    return np.array(
        [*entry["m_left"], entry["c_left"], *entry["m_right"], entry["c_right"]]  # type: ignore[misc]
    )


def test_replay_runs_each_joint_and_keys_the_json_by_joint(
    arm_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out, report = tmp_path / "out", tmp_path / "report"
    code = main(
        [
            "replay",
            str(arm_bag),
            *TOPICS,
            "--joint",
            "shoulder,elbow",
            "--joint",
            "wrist",
            "--command-index",
            "0",
            "--command-index",
            "2,3",
            "-o",
            str(out),
            "--report",
            str(report),
            "--json",
            "--no-progress",
        ]
    )
    assert code == 0
    got = json.loads(capsys.readouterr().out)
    assert list(got) == list(NAMES)
    for name, model in zip(NAMES, MODELS, strict=True):
        estimate = np.array(list(got[name]["parameters"].values()))
        assert np.max(np.abs(estimate - model.parameters())) < 0.02, name
        assert (out / name / "genbacklash-output.json").exists()  # a bag per joint
        assert (report / name / "index.html").exists()
    index = (report / "index.html").read_text()
    assert all(f'href="{name}/index.html"' in index for name in NAMES)


def test_identify_runs_each_joint(arm_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        [
            "identify",
            str(arm_bag),
            *TOPICS,
            "--joint",
            "shoulder,elbow,wrist",
            "--command-index",
            "0,2,3",
            "--json",
        ]
    )
    assert code == 0
    got = json.loads(capsys.readouterr().out)
    assert list(got) == list(NAMES)
    plays = []
    for name, model in zip(NAMES, MODELS, strict=True):
        assert got[name]["model"] == "backlash" and got[name]["converged"], name
        error = np.max(np.abs(_params(got[name]["backlash"]) - model.parameters()))
        assert error < 0.02, (name, error)
        plays.append(got[name]["play"])
    assert plays[1] > plays[0] > plays[2]  # the elbow's play is the widest, the wrist's least


def test_identify_text_has_a_heading_per_joint_and_a_checkpoint_each(
    arm_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    checkpoint = tmp_path / "start_{joint}.json"
    code = main(
        [
            "identify",
            str(arm_bag),
            *TOPICS,
            "--joint",
            "elbow",
            "--joint",
            "wrist",
            "--command-index",
            "2",
            "--command-index",
            "3",
            "--checkpoint",
            str(checkpoint),
        ]
    )
    assert code == 0
    out = capsys.readouterr().out
    assert out.index("== joint elbow ==") < out.index("== joint wrist ==")
    assert (tmp_path / "start_elbow.json").exists() and (tmp_path / "start_wrist.json").exists()


def test_diagnose_runs_each_joint(arm_bag: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code = main(
        [
            "diagnose",
            str(arm_bag),
            *TOPICS,
            "--joint",
            "shoulder,wrist",
            "--command-index",
            "0,3",
            "--json",
        ]
    )
    assert code == 0
    got = json.loads(capsys.readouterr().out)
    assert list(got) == ["shoulder", "wrist"]
    assert all("misfit_final" in got[name] for name in got)


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--joint", "shoulder,elbw", "--command-index", "0,2"], r"elbw.*shoulder|close"),
        (["--joint", "shoulder,elbow", "--command-index", "0"], r"one --command-index per"),
        (["--joint", "shoulder,elbow"], r"Float64MultiArray: give each joint's element"),
        (["--joint", "a,a", "--command-index", "0,2"], r"lists a joint twice"),
        (["--command-index", "0,2"], r"need as many --joint"),
        (
            ["--joint", "shoulder,elbow", "--command-index", "0,2", "--checkpoint", "x.json"],
            r"must hold '\{joint\}'",
        ),
    ],
)
def test_a_bad_selection_stops_before_any_work(
    arm_bag: Path, extra: list[str], match: str, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["identify", str(arm_bag), *TOPICS, *extra, "--json"]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""  # nothing identified
    assert len(captured.err.strip().splitlines()) == 1
    assert re.search(match, captured.err), captured.err


def test_a_node_params_file_with_joints_serves_the_commands_too(
    arm_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The node's multi-joint params file is checked as the node checks it; the commands
    take their joints from --joint and say the file's are not used."""
    params = tmp_path / "arm.yaml"
    body = "    joints: [shoulder, elbow]\n    command_indices: [0, 2]\n    {j}:\n      degree: 2\n"
    params.write_text("/**/backlash_identifier:\n  ros__parameters:\n" + body.format(j="elbow"))
    args = ["identify", str(arm_bag), *TOPICS, "--joint", "wrist", "--command-index", "3"]
    assert main([*args, "--params-file", str(params), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["converged"]
    assert "joints, command_indices, elbow.degree not used by identify" in captured.err
    params.write_text("/**/backlash_identifier:\n  ros__parameters:\n" + body.format(j="elbw"))
    assert main([*args, "--params-file", str(params), "--json"]) == 2
    assert "'elbw' is not in 'joints' (close matches: elbow)" in capsys.readouterr().err


def _tree(path: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(path)): p.read_bytes() for p in sorted(path.rglob("*")) if p.is_file()
    }


def test_overwrite_of_several_joints_replaces_only_their_bags(
    arm_bag: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``-o OUT`` with several joints is a directory of one bag per joint: ``--overwrite``
    replaces those bags (genbacklash wrote them) and nothing else in OUT; without it an
    existing joint's bag stops the run; a joint's bag genbacklash did not write, or an OUT
    that is a file, is never removed; an OUT holding the input is refused."""
    out = tmp_path / "out"
    args = ["replay", str(arm_bag), *TOPICS, "--joint", "shoulder,elbow"]
    args += ["--command-index", "0,2", "-o", str(out), "--no-progress", "--json"]
    assert main(args) == 0
    first = _tree(out)
    (out / "notes.txt").write_text("mine")  # the user's, beside the joints' bags
    other = out / "wrist"  # another run's joint, not selected now
    other.mkdir()
    (other / "keep.txt").write_text("keep")
    capsys.readouterr()

    assert main(args) == 2  # exists already
    assert "exists already" in capsys.readouterr().err
    assert main([*args, "--overwrite"]) == 0
    capsys.readouterr()
    again = _tree(out)
    assert again.pop("notes.txt") == b"mine" and again.pop("wrist/keep.txt") == b"keep"
    assert again.keys() == first.keys()  # the same bags, written anew
    assert (out / "shoulder" / "genbacklash-output.json").is_file()

    # a joint's directory genbacklash did not write: refused, nothing removed
    (out / "elbow" / "genbacklash-output.json").unlink()
    before = _tree(out)
    assert main([*args, "--overwrite"]) == 2
    err = capsys.readouterr().err
    assert "not removing it" in err and f"{out}/elbow" in err, err
    assert _tree(out) == before

    # OUT a file: refused, kept
    plain = tmp_path / "plain.txt"
    plain.write_text("keep")
    plain_args = [*args[: args.index("-o")], "-o", str(plain), "--no-progress", "--overwrite"]
    assert main(plain_args) == 2
    assert "is not a directory" in capsys.readouterr().err
    assert plain.read_text() == "keep"

    # OUT holding the input bag: refused before anything is touched
    holder = arm_bag.parent
    before = _tree(holder)
    holder_args = [*args[: args.index("-o")], "-o", str(holder), "--overwrite", "--no-progress"]
    assert main(holder_args) == 2
    assert "contains the input" in capsys.readouterr().err
    assert _tree(holder) == before
