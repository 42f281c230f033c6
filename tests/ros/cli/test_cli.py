"""The genbacklash command line: contracts, exit codes and messages."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import paper_example
from genbacklash_ros.bags.csvio import Series, read_series_csv, write_series_csv
from genbacklash_ros.cli.main import (
    EXIT_BAD_INPUT,
    EXIT_BROKEN_PIPE,
    EXIT_NOT_CONVERGED,
    EXIT_OK,
    build_parser,
    main,
)


def _simulate(tmp_path: Path, example: int, seed: int = 0) -> Path:
    out = tmp_path / f"ex{example}.csv"
    assert main(["simulate", "--example", str(example), "--seed", str(seed), "-o", str(out)]) == 0
    return out


def test_simulate_writes_the_papers_setting(tmp_path: Path) -> None:
    series = read_series_csv(_simulate(tmp_path, 1, seed=4))
    expected = paper_example(1).generate(4)
    assert series.u.size == 800
    assert np.array_equal(series.u, expected.u)
    assert np.array_equal(series.y, expected.y)


def test_simulate_options(tmp_path: Path) -> None:
    out = tmp_path / "short.csv"
    assert (
        main(["simulate", "--example", "3", "--samples", "300", "--snr", "5", "-o", str(out)]) == 0
    )
    assert read_series_csv(out).u.size == 300


def _names(result: dict[str, object]) -> list[str]:
    backlash = result["backlash"]
    assert isinstance(backlash, dict)
    n = len(backlash["m_left"])
    names = [f"m_left_{k}" for k in range(1, n + 1)] + ["c_left"]
    names += [f"m_right_{k}" for k in range(1, n + 1)] + ["c_right"]
    linear = result.get("linear")
    if isinstance(linear, dict):
        names += [f"a_{k}" for k in range(2, len(linear["a"]) + 1)]
        names += [f"b_{k}" for k in range(1, len(linear["b"]) + 1)]
    return names


@pytest.mark.parametrize("example", [1, 3])
def test_identify_json_contract(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], example: int
) -> None:
    data = _simulate(tmp_path, example)
    model = "cascade" if example == 3 else "backlash"
    assert main(["identify", str(data), "--model", model, "--json"]) == EXIT_OK
    result = json.loads(capsys.readouterr().out)
    expected_keys = {"model", "backlash", "iterations", "converged", "fit", "reason"}
    # issue 22: the play c_L + c_R with its standard deviation, the parameters' ones
    expected_keys |= {"play", "play_std", "parameter_std"}
    # ... in two parts: the noise's and the model error's (issue 22, deliverable 3)
    expected_keys |= {
        f"{key}_{part}"
        for key in ("play_std", "parameter_std")
        for part in ("statistical", "model")
    }
    expected_keys |= {"model_error_dominates", "misfit_correlated"}
    if model == "cascade":
        expected_keys.add("linear")
        assert result["linear"]["a"][0] == 1.0
        assert len(result["linear"]["a"]) == 2 and len(result["linear"]["b"]) == 2
    assert set(result) == expected_keys
    assert result["model"] == model
    assert set(result["backlash"]) == {"m_left", "c_left", "m_right", "c_right"}
    truth = paper_example(example).backlash
    assert abs(result["backlash"]["m_left"][0] - truth.m_left[0]) < 0.03
    assert abs(result["backlash"]["c_right"] - truth.c_right) < 0.03
    assert result["converged"] is True
    assert isinstance(result["iterations"], int)
    assert 0.0 < result["fit"]["nrmse"] < 0.1
    assert result["fit"]["misfit"] == result["fit"]["nrmse"]
    play = result["backlash"]["c_left"] + result["backlash"]["c_right"]
    assert result["play"] == pytest.approx(play)
    assert 0.0 < result["play_std"] < 0.05
    assert abs(result["play"] - (truth.c_left + truth.c_right)) < 4 * result["play_std"]
    assert set(result["parameter_std"]) == set(_names(result))
    assert all(0.0 < s < 0.1 for s in result["parameter_std"].values())
    # the paper's examples are the model itself with white noise: no model-error part
    assert result["play_std_model"] == 0.0 and result["misfit_correlated"] == 0.0
    assert result["play_std"] == result["play_std_statistical"]
    assert result["model_error_dominates"] is False


def test_identify_table_and_plots(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    data = _simulate(tmp_path, 2)
    plots = tmp_path / "plots"
    assert main(["identify", str(data), "--degree", "3", "--plot", str(plots)]) == EXIT_OK
    out = capsys.readouterr().out
    assert "m_left_1" in out and "converged after" in out
    assert (plots / "characteristic.png").stat().st_size > 1000
    assert (plots / "history.png").stat().st_size > 1000


def test_identify_reports_nonfinite_samples(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ex = paper_example(1).generate(0)
    u = ex.u.copy()
    u[[10, 20, 30]] = np.nan
    path = tmp_path / "nan.csv"
    write_series_csv(path, Series(u=u, y=ex.y))
    assert main(["identify", str(path)]) == EXIT_BAD_INPUT
    err = capsys.readouterr().err
    assert "line 12 of" in err and "column 'u': 'nan' is not finite" in err
    assert "(3 rows are bad: lines 12, 22 and 32)" in err
    assert main(["identify", str(path), "--drop-nonfinite", "--json"]) == EXIT_OK
    err = capsys.readouterr().err
    assert "dropped 3 rows of" in err and "lines 12, 22 and 32" in err


def test_identify_not_enough_excitation(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "ramp.csv"
    u = np.linspace(0.0, 1.0, 200)
    write_series_csv(path, Series(u=u, y=u))
    assert main(["identify", str(path)]) == EXIT_BAD_INPUT
    assert "not enough excitation" in capsys.readouterr().err


def test_identify_not_converged_exit_code(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    ex = paper_example(3)
    data = ex.generate(0)
    delayed = np.concatenate([np.zeros(5), data.y[:-5]])  # a dead time the model lacks
    path = tmp_path / "delayed.csv"
    write_series_csv(path, Series(u=data.u, y=delayed))
    assert main(["identify", str(path), "--model", "cascade", "--json"]) == EXIT_NOT_CONVERGED
    result = json.loads(capsys.readouterr().out)
    assert result["converged"] is False
    assert "singular" in result["reason"]


def test_missing_file_and_bag(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["identify", str(tmp_path / "none.csv")]) == EXIT_BAD_INPUT
    assert "does not exist" in capsys.readouterr().err
    (tmp_path / "x.mcap").write_bytes(b"\x89MCAP0\r\n")
    assert main(["identify", str(tmp_path / "x.mcap")]) == EXIT_BAD_INPUT
    assert "--command TOPIC" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["identify", "simulate", "demo"])
def test_every_command_has_help(command: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        build_parser().parse_args([command, "--help"])
    assert exit_info.value.code == 0
    assert "usage: genbacklash" in capsys.readouterr().out


def test_bad_option_values_are_rejected(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit):
        build_parser().parse_args(["identify", "d.csv", "--degree", "0"])
    assert "must be >= 1" in capsys.readouterr().err


def test_demo_runs_as_a_console_script(tmp_path: Path) -> None:
    out = tmp_path / "demo"
    proc = subprocess.run(
        [sys.executable, "-m", "genbacklash_ros.cli.main", "demo", "--out", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr
    assert "truth" in proc.stdout and "c_right" in proc.stdout
    for name in ("characteristic.png", "history.png", "result.json", "data.csv"):
        assert (out / name).exists()
    assert json.loads((out / "result.json").read_text())["model"] == "cascade"


@pytest.mark.parametrize("unbuffered", [True, False])
def test_closed_stdout_ends_quietly(tmp_path: Path, unbuffered: bool) -> None:
    """`genbacklash identify DATA | head -1`: the reader leaves early; no traceback, with a
    buffered stdout too (its last flush failed at the interpreter's exit, status 120)."""
    data = _simulate(tmp_path, 1)
    env = {k: v for k, v in os.environ.items() if k != "PYTHONUNBUFFERED"}
    if unbuffered:
        env["PYTHONUNBUFFERED"] = "1"
    proc = subprocess.Popen(
        [sys.executable, "-m", "genbacklash_ros.cli.main", "identify", str(data)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
    )
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()  # as `head` does once it has its line, before the table is printed
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=120) == EXIT_BROKEN_PIPE
    assert stderr == ""


def test_the_command_line_starts_without_scipy_signal_or_stats() -> None:
    """``genbacklash replay`` of a backlash never filters or tests: importing the command
    line must not import scipy.signal or scipy.stats (0.5 s of a 3 s replay of a 5-minute bag
    was their import)."""
    code = (
        "import sys, genbacklash_ros.cli.main; "
        "print(sorted(m for m in ('scipy.signal', 'scipy.stats') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_a_command_imports_only_its_own_module() -> None:
    """main() builds the parser of the command named (the others' modules stay unimported:
    start-up time of `genbacklash replay`), while `genbacklash --help` still lists them all."""
    code = (
        "import sys\n"
        "from genbacklash_ros.cli.main import main\n"
        "try:\n"
        "    main(['replay', '--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "names = ('genbacklash_ros.cli.diagnose', 'genbacklash_ros.cli.fleet',\n"
        "         'genbacklash_ros.cli.excite', 'genbacklash_ros.cli.export',\n"
        "         'genbacklash_core.diagnose')\n"
        "print(sorted(m for m in names if m in sys.modules), file=sys.stderr)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert "usage: genbacklash replay" in out.stdout
    assert out.stderr.strip() == "[]"
    listed = build_parser().format_help()
    commands = ("identify", "diagnose", "replay", "node", "excite", "fleet", "fleet-report")
    for command in (*commands, "export", "readings"):
        assert command in listed


def test_only_the_console_scripts_own_call_freezes_what_is_left_for_the_exit(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The console script's process ends after main(): what is still alive then is frozen,
    so that the interpreter's final collection does not walk it (rosbags' typestore, a
    replay's history). A program that calls main(argv) keeps its collector as it was."""
    data = _simulate(tmp_path, 1)
    gc.unfreeze()
    try:
        assert main(["identify", str(data)]) == 0
        assert gc.get_freeze_count() == 0
        monkeypatch.setattr(sys, "argv", ["genbacklash", "identify", str(data)])
        assert main() == 0
        assert gc.get_freeze_count() > 0
    finally:
        gc.unfreeze()


def test_the_command_line_starts_openblas_on_one_thread() -> None:
    """Importing the command line tells OpenBLAS one thread before numpy loads it (every
    command limits the BLAS to one anyway: its threads would only start and spin), and
    keeps a value the caller set."""
    code = (
        "import os, sys; import genbacklash_ros.cli.main; "
        "sys.stdout.write(os.environ['OPENBLAS_NUM_THREADS'])"
    )
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    seen = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True
    ).stdout
    kept = subprocess.run(
        [sys.executable, "-c", code],
        env={**env, "OPENBLAS_NUM_THREADS": "3"},
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    assert (seen, kept) == ("1", "3")


def test_every_command_runs_with_one_blas_thread(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The batch fits' last bits depend on how many threads the BLAS sums with, and a
    diagnosis can carry that far (genbacklash_ros.blas_threads): every command runs with one,
    as the node and replay do, whatever the machine's cores. Run under a limit of two, the
    command sees one, and two again after it."""
    threadpoolctl = pytest.importorskip("threadpoolctl")
    from genbacklash_ros.cli import main as cli_main

    def blas_threads() -> int:
        infos = [i for i in threadpoolctl.threadpool_info() if i["user_api"] == "blas"]
        assert infos, "numpy's BLAS is not seen by threadpoolctl"
        return max(int(i["num_threads"]) for i in infos)

    data = _simulate(tmp_path, 1)
    seen: list[int] = []
    real_check = cli_main.check_paths

    def check_then_probe(args: object) -> None:
        real_check(args)
        args.func = lambda _args: seen.append(blas_threads()) or 0  # type: ignore[attr-defined]

    monkeypatch.setattr(cli_main, "check_paths", check_then_probe)
    with threadpoolctl.threadpool_limits(limits=2, user_api="blas"):
        assert blas_threads() == 2
        for words in (["identify", str(data)], ["diagnose", str(data)]):
            assert main(words) == 0
        assert blas_threads() == 2
    assert seen == [1, 1]
