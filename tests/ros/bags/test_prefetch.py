"""Reading a bag one block ahead in a child process (genbacklash_ros.bags.prefetch): the same
messages and the same damage as the in-process reader, no child where one must not run, and
no child left behind after Ctrl-C or SIGTERM."""

from __future__ import annotations

import hashlib
import multiprocessing
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

from genbacklash_ros.bags import replay as replay_module
from genbacklash_ros.bags.bagio import BagError, BagReader
from genbacklash_ros.bags.prefetch import ENV, PrefetchedMessages, can_prefetch
from genbacklash_ros.bags.replay import replay
from genbacklash_ros.bags.simbags import (
    COMMAND_TOPIC,
    ENCODER_TOPIC,
    JOINT,
    operation_settings,
    write_example_bag,
    write_operation_bag,
)

BENCH = Path(__file__).resolve().parents[3] / "bench"
BUNDLED = Path(__file__).resolve().parents[3] / "bags" / "operation"
TOPICS = [COMMAND_TOPIC, ENCODER_TOPIC]
SELECTION = {"command_topic": COMMAND_TOPIC, "encoder_topic": ENCODER_TOPIC, "joint": JOINT}


@pytest.fixture(scope="module")
def shapes() -> Iterator[object]:
    sys.path.insert(0, str(BENCH))
    try:
        import _replay_shapes  # type: ignore[import-not-found]

        yield _replay_shapes
    finally:
        sys.path.remove(str(BENCH))


def _in_process(bag: Path, topics: list[str]) -> tuple[list[tuple[object, ...]], str]:
    """The in-process reader's messages (as tuples) and its error text ('' for none)."""
    got: list[tuple[object, ...]] = []
    with BagReader(bag) as reader:
        try:
            for item in reader.raw_messages(topics):
                got.append(tuple(item))
        except BagError as err:
            return got, str(err)
    return got, ""


def _prefetched(bag: Path, topics: list[str], block: int) -> tuple[list[tuple[object, ...]], str]:
    got: list[tuple[object, ...]] = []
    with PrefetchedMessages(bag, topics, block) as source:
        try:
            for item in source:
                got.append(tuple(item))
        except BagError as err:
            return got, str(err)
    return got, ""


def _same_reading(bag: Path, topics: list[str], block: int = 1000) -> int:
    want, want_error = _in_process(bag, topics)
    got, error = _prefetched(bag, topics, block)
    assert got == want
    assert error == want_error
    return len(want)


@pytest.mark.parametrize("name", ["operation", "float64", "arm6", "physics"])
def test_the_prefetched_messages_are_the_readers_on_every_shape(
    name: str, shapes: object, tmp_path: Path
) -> None:
    if name == "physics":
        pytest.importorskip("mujoco")
    bag = tmp_path / name
    shapes.SHAPES[name].write(bag, 3.0, 7)  # type: ignore[attr-defined]
    assert _same_reading(bag, TOPICS) > 3000  # several blocks and a shorter last one


def test_the_bundled_bag_and_one_message_blocks(tmp_path: Path) -> None:
    assert _same_reading(BUNDLED, TOPICS, block=8192) == 32412
    bag = tmp_path / "ex1"
    write_example_bag(bag, 1, seed=2, n_samples=300)
    assert _same_reading(bag, TOPICS, block=1) == 600
    assert _same_reading(bag, [ENCODER_TOPIC], block=7) == 300


def _flip(bag: Path, start: float, length: int) -> None:
    (file,) = bag.glob("*.mcap")
    data = bytearray(file.read_bytes())
    at = int(len(data) * start)
    for i in range(at, min(at + length, len(data))):
        data[i] ^= 0xFF
    file.write_bytes(bytes(data))


def _truncate(bag: Path, fraction: float) -> None:
    (file,) = bag.glob("*.mcap")
    file.write_bytes(file.read_bytes()[: int(file.stat().st_size * fraction)])


@pytest.mark.parametrize(
    "damage",
    [
        lambda bag: _truncate(bag, 0.6),
        lambda bag: _truncate(bag, 0.05),
        lambda bag: _flip(bag, 0.5, 64),
        lambda bag: _flip(bag, 0.97, 200),  # the summary: rosbags' indexes
        lambda bag: (bag / "metadata.yaml").unlink(),
    ],
    ids=["cut", "cut-early", "chunk", "summary", "no-metadata"],
)
def test_a_damaged_bag_gives_the_same_messages_then_the_same_error(
    damage: Callable[[Path], None], tmp_path: Path
) -> None:
    bag = tmp_path / "bag"
    shutil.copytree(BUNDLED, bag)
    damage(bag)
    before = {f.name: f.read_bytes() for f in bag.iterdir()}
    _, want_error = _in_process(bag, TOPICS)
    assert want_error  # the damage shows
    _same_reading(bag, TOPICS, block=4096)
    assert {f.name: f.read_bytes() for f in bag.iterdir()} == before  # nothing written in


def test_a_bag_gone_before_the_child_opens_it_is_one_line_error(tmp_path: Path) -> None:
    got, error = _prefetched(tmp_path / "gone", TOPICS, 100)
    assert got == []
    assert error == f"no bag at {tmp_path / 'gone'}: the path does not exist"


def test_the_child_ends_with_the_reading_and_after_close(tmp_path: Path) -> None:
    source = PrefetchedMessages(BUNDLED, TOPICS, 512)
    stream = iter(source)
    next(stream)
    process = source._process
    assert process.is_alive()
    source.close()  # part-way: the child's send fails, it ends
    assert process.exitcode is not None
    with PrefetchedMessages(BUNDLED, TOPICS, 8192) as whole:
        assert sum(1 for _ in whole) == 32412
    assert whole._process.exitcode == 0


# --------------------------------------------------------------------------- where not


def test_no_child_with_the_variable_at_0_or_a_second_thread(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._threads", lambda: 1)
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._cpus", lambda: 2)
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._load", lambda: 1.5)
    monkeypatch.delenv(ENV, raising=False)
    assert can_prefetch() == (threading.active_count() == 1)
    monkeypatch.setenv(ENV, "0")
    assert not can_prefetch()
    monkeypatch.delenv(ENV)
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._load", lambda: 2.0)
    assert not can_prefetch()  # no CPU free: the child would compete with the replay
    monkeypatch.setenv(ENV, "1")
    assert can_prefetch() == (threading.active_count() == 1)  # whatever the load
    monkeypatch.delenv(ENV)
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._load", lambda: 0.0)
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._cpus", lambda: 1)
    assert not can_prefetch()  # one CPU: nothing to gain
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._cpus", lambda: 2)
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._threads", lambda: 3)
    assert not can_prefetch()  # native threads (OpenBLAS's): a fork is unsafe
    monkeypatch.setattr("genbacklash_ros.bags.prefetch._threads", lambda: None)
    assert not can_prefetch()  # the OS does not say


def test_the_os_counts_a_second_thread() -> None:
    from genbacklash_ros.bags.prefetch import _threads

    before = _threads()
    assert before is not None and before >= 1
    stop = threading.Event()
    thread = threading.Thread(target=stop.wait)
    thread.start()
    try:
        assert _threads() == before + 1
        assert not can_prefetch()
    finally:
        stop.set()
        thread.join()


def _daemon_replay(bag: str, out: str, answers: multiprocessing.Queue) -> None:  # type: ignore[type-arg]
    from genbacklash_ros.bags import prefetch

    result = replay(bag, out, **SELECTION)  # type: ignore[arg-type]
    answers.put((prefetch.can_prefetch(), result.messages_in, result.messages_out))


def _records(bag: Path) -> str:
    digest = hashlib.sha256()
    with BagReader(bag) as reader:
        for item in reader.raw_messages(list(reader.topics)):
            digest.update(item.topic.encode())
            digest.update(item.log_time_ns.to_bytes(8, "little"))
            digest.update(item.raw)
    return digest.hexdigest()


def test_a_daemonic_process_replays_in_process(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """multiprocessing allows a daemonic process no child (genbacklash fleet's workers)."""
    monkeypatch.setenv(ENV, "1")  # not for the load
    context = multiprocessing.get_context("fork")
    answers = context.Queue()
    worker = context.Process(
        target=_daemon_replay, args=(str(BUNDLED), str(tmp_path / "d"), answers), daemon=True
    )
    worker.start()
    prefetched, n_in, n_out = answers.get(timeout=120)
    worker.join(30)
    assert worker.exitcode == 0
    assert prefetched is False
    mine = replay(BUNDLED, tmp_path / "m", **SELECTION, prefetch=False)  # type: ignore[arg-type]
    assert (n_in, n_out) == (mine.messages_in, mine.messages_out)
    assert _records(tmp_path / "d") == _records(tmp_path / "m")


def test_a_prefetched_replay_is_the_in_process_one_and_counts_its_progress(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    steps: list[int] = []
    made: list[PrefetchedMessages] = []

    class Counted(replay_module._Progress):
        def step(self, count: int = 1) -> None:
            steps.append(count)
            super().step(count)

    class Recorded(PrefetchedMessages):
        def __init__(self, *args: object) -> None:
            super().__init__(*args)  # type: ignore[arg-type]
            made.append(self)

    monkeypatch.setattr(replay_module, "_Progress", Counted)
    monkeypatch.setattr(replay_module, "PrefetchedMessages", Recorded)
    monkeypatch.setattr(replay_module, "can_prefetch", lambda: True)
    monkeypatch.setattr(replay_module, "_BLOCK", 5000)
    ahead = replay(BUNDLED, tmp_path / "a", **SELECTION, progress=True)  # type: ignore[arg-type]
    assert len(made) == 1 and made[0]._process.exitcode == 0
    assert sum(steps) == ahead.messages_in == 32412
    steps.clear()
    here = replay(BUNDLED, tmp_path / "h", **SELECTION, prefetch=False)  # type: ignore[arg-type]
    assert len(made) == 1
    assert sum(steps) == here.messages_in
    assert ahead.to_dict() | {"output": ""} == here.to_dict() | {"output": ""}
    assert _records(tmp_path / "a") == _records(tmp_path / "h")


# --------------------------------------------------------------------------- signals


@pytest.fixture(scope="module")
def long_bag(tmp_path_factory: pytest.TempPathFactory) -> Path:
    bag = tmp_path_factory.mktemp("long") / "op"
    write_operation_bag(bag, operation_settings((("operation", 120.0),)), seed=5)
    return bag


def _children(pid: int) -> list[int]:
    try:
        text = Path(f"/proc/{pid}/task/{pid}/children").read_text()
    except OSError:
        return []
    return [int(c) for c in text.split()]


def _gone(pid: int, within: float) -> bool:
    """Whether ``pid`` has ended (or is a zombie nobody reaps) within ``within`` seconds."""
    end = time.monotonic() + within
    while time.monotonic() < end:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            return True
        if state in ("Z", "X"):
            return True
        time.sleep(0.01)
    return False


def _start_replay(bag: Path, out: Path) -> tuple[subprocess.Popen[str], int]:
    """A real ``genbacklash replay`` process, and its reading child once it runs."""
    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", ENV: "1"}  # a child whatever the load
    code = "import sys; from genbacklash_ros.cli.main import main; sys.exit(main())"
    args = ["replay", str(bag), "--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC]
    proc = subprocess.Popen(
        [sys.executable, "-c", code, *args, "--joint", JOINT, "-o", str(out), "--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
        start_new_session=True,  # its own process group: a terminal's Ctrl-C goes to both
    )
    end = time.monotonic() + 60
    while time.monotonic() < end and proc.poll() is None:
        children = _children(proc.pid)
        if children:
            return proc, children[0]
        time.sleep(0.002)
    proc.kill()
    raise AssertionError(f"no reading child seen (exit {proc.poll()})")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_ctrl_c_stops_the_replay_and_its_child_quietly(long_bag: Path, tmp_path: Path) -> None:
    proc, child = _start_replay(long_bag, tmp_path / "out")
    time.sleep(0.2)  # well into the replay
    os.killpg(proc.pid, signal.SIGINT)  # what a terminal's Ctrl-C does: the whole group
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130
    assert err.strip() == "genbacklash replay: interrupted"  # nothing from the child
    assert _gone(child, 5)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_the_child_does_not_outlive_a_terminated_replay(long_bag: Path, tmp_path: Path) -> None:
    proc, child = _start_replay(long_bag, tmp_path / "out")
    time.sleep(0.2)
    os.kill(proc.pid, signal.SIGTERM)  # the parent alone
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == -signal.SIGTERM
    assert err == ""
    assert _gone(child, 5)


def test_the_command_line_can_read_in_process(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    from genbacklash_ros.cli import replay as cli_replay
    from genbacklash_ros.cli.main import main

    asked: list[object] = []

    def spy(*args: object, **kwargs: object) -> object:
        asked.append(kwargs["prefetch"])
        return replay(*args, **kwargs)  # type: ignore[arg-type]

    monkeypatch.setattr(cli_replay, "replay", spy)
    args = ["replay", str(BUNDLED), "--command", COMMAND_TOPIC, "--encoder", ENCODER_TOPIC]
    args += ["--joint", JOINT, "--no-progress", "--json"]
    assert main([*args, "-o", str(tmp_path / "a")]) == 0
    assert main([*args, "-o", str(tmp_path / "b"), "--no-prefetch"]) == 0
    assert asked == [True, False]
