"""``genbacklash demo --live``: a simulated arm and the identifier node, in one ROS 2 graph.

Two ROS 2 nodes start:

* ``backlash_identifier`` (``genbacklash node``, a process of its own, rclpy or plain DDS):
  subscribes ``/command`` and ``/joint_states``, publishes ``/compensated_command``, its
  estimates and ``/diagnostics``, exactly as beside a real arm;
* ``simulated_arm`` (this process, rclpy): physics drivetrains
  (:class:`~genbacklash_ros.demo.arm.SimulatedArm`) that publish ``/joint_states`` and
  *obey* ``/compensated_command``, while a controller inside it sends the desired moves on
  ``/command`` (100 Hz, a ``Float64MultiArray``, one element per joint and a last one, the
  command's number, which the node passes through untouched: the arm knows which command
  each answer is for, and its uncompensated twins take that command at the same moment).

Once a second a line per joint shows what happens: the play the node estimates against the
drivetrain's geometric play, the load tracking error of the arm (on the compensated commands)
against its uncompensated twin over the last second, and whether compensation is on, faded or
off. A table closes the run: the second half's cut, what two uncompensated twins differ by
there, and the cut over the readings while compensation acted; harm is called only beyond
that spread (:mod:`genbacklash_ros.demo.verdict`). Nothing is written to disk but the
node's log, in a temporary directory that is removed afterwards unless the node failed.

Needs rclpy (``pip install 'genbacklash[ros]'``) and mujoco (``[physics]``).
"""

from __future__ import annotations

import heapq
import math
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from genbacklash_core import GenBacklashError
from genbacklash_ros.demo.arm import ArmSettings, SimulatedArm
from genbacklash_ros.demo.verdict import DemoVerdict

__all__ = ["LiveResult", "main_live", "node_params_yaml", "run_live"]

NODE_NAME = "backlash_identifier"
ANSWER_NS = 1_000_000  # the arm first looks for the answer to a command this long after it (ns)
POLL_NS = 1_000_000  # then, until it comes, every POLL_NS (a drive's 1 kHz control loop)
MATCH_TIMEOUT_S = 60.0  # the node's start (imports, DDS discovery) before the arm gives up


@dataclass(frozen=True)
class LiveResult:
    """What the live demo saw, per joint in ``joints`` order (for the closing table and
    tests)."""

    joints: tuple[str, ...]
    geometric_play: float
    play: tuple[float, ...]
    compensated_rms: tuple[float, ...]
    uncompensated_rms: tuple[float, ...]
    compensation: tuple[str, ...]
    commands_sent: int
    commands_answered: int
    behind_s: float
    verdicts: tuple[DemoVerdict, ...] = ()


def node_params_yaml(joints: tuple[str, ...], thread_priority: int = 0) -> str:
    """The identifier node's parameters for the arm: its JointState and command array (and
    ``thread_priority`` when above 0).

    >>> "thread_priority: 20" in node_params_yaml(("a",), thread_priority=20)
    True
    """
    lines = [
        f"/**/{NODE_NAME}:",
        "  ros__parameters:",
        "    command_type: float64_multi_array",
        "    encoder_type: joint_state",
        # the arm obeys /compensated_command: the gear's input is the command the node sent
        "    compensation_in_loop: true",
    ]
    if len(joints) == 1:
        lines += [f"    joint: {joints[0]}", "    command_index: 0"]
    else:
        names = ", ".join(joints)
        indices = ", ".join(str(k) for k in range(len(joints)))
        lines += [f"    joints: [{names}]", f"    command_indices: [{indices}]"]
    if thread_priority > 0:
        lines.append(f"    thread_priority: {thread_priority}")
    return "\n".join(lines) + "\n"


class _Inbox:
    """What the arm's subscriptions received (written by the executor's thread)."""

    def __init__(self, joints: tuple[str, ...]) -> None:
        self.lock = threading.Lock()
        self.command: tuple[float, ...] | None = None  # the latest answer, its number last
        self.answered = 0
        self.play: dict[str, float] = {j: math.nan for j in joints}
        self.state: dict[str, str] = {j: "?" for j in joints}
        self.reason: dict[str, str] = {j: "" for j in joints}
        self.shown: dict[str, str] = {j: "?" for j in joints}  # the state the last line gave


def _estimate_callback(inbox: _Inbox, joint: str) -> Callable[[Any], None]:
    def take(msg: Any) -> None:
        names = msg.layout.dim[0].label.split(",") if msg.layout.dim else []
        values = dict(zip(names, msg.data, strict=False))
        if "c_left" in values and "c_right" in values:
            with inbox.lock:
                inbox.play[joint] = float(values["c_left"] + values["c_right"])

    return take


def _diagnostics_callback(inbox: _Inbox, joints: tuple[str, ...]) -> Callable[[Any], None]:
    def take(msg: Any) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            state = values.get("compensation_state")
            if state is None:
                continue
            joint = next((j for j in joints if status.name.endswith(j)), None)
            if joint is None and len(joints) == 1:
                joint = joints[0]
            if joint is not None:
                with inbox.lock:
                    inbox.state[joint] = state
                    inbox.reason[joint] = values.get("compensation_reason", "")

    return take


def _mrad(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{1e3 * value:.1f}"


def run_live(
    settings: ArmSettings,
    *,
    transport: str = "rclpy",
    log: Callable[[str], None] = print,
    thread_priority: int = 0,
) -> LiveResult:
    """Start the identifier node (``thread_priority``: the node's parameter), run the arm for
    ``settings.duration`` s, stop the node.

    Raises
    ------
    GenBacklashError
        rclpy or mujoco missing, or the node did not start or died (its log's last lines).
    """
    try:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import qos_profile_sensor_data
    except ImportError as err:
        raise GenBacklashError(
            f"demo --live needs rclpy ({err}): pip install 'genbacklash[ros]'"
        ) from err
    try:
        import mujoco  # noqa: F401
    except ImportError as err:
        raise GenBacklashError(
            f"demo --live needs mujoco ({err}): pip install 'genbacklash[physics]'"
        ) from err
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray

    arm = SimulatedArm(settings)
    joints = settings.joints
    workdir = Path(tempfile.mkdtemp(prefix="genbacklash-demo-"))
    params = workdir / "params.yaml"
    params.write_text(node_params_yaml(joints, thread_priority), encoding="utf-8")
    node_log = workdir / "node.log"
    command = [
        sys.executable,
        "-m",
        "genbacklash_ros.cli.main",
        "node",
        "--transport",
        transport,
        "--params-file",
        str(params),
        "--remap",
        "encoder:=/joint_states",
    ]
    log(
        f"demo --live: {len(joints)} joint(s) of the physics drivetrain '{settings.variant}' "
        f"(servo {settings.bandwidth:g} Hz, geometric play {_mrad(arm.play)} mrad), "
        f"{settings.duration:g} s; starting the identifier node ({transport})"
    )
    failed = True
    with open(node_log, "wb") as out:
        node_proc = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT)
    rclpy.init()
    node = rclpy.create_node("simulated_arm")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinner = threading.Thread(target=executor.spin, daemon=True)
    inbox = _Inbox(joints)
    try:
        cmd_pub = node.create_publisher(Float64MultiArray, "/command", 10)
        enc_pub = node.create_publisher(JointState, "/joint_states", qos_profile_sensor_data)

        def take_command(msg: Any) -> None:
            with inbox.lock:
                inbox.command = tuple(msg.data)
                inbox.answered += 1

        comp_sub = node.create_subscription(
            Float64MultiArray, "/compensated_command", take_command, 10
        )
        for joint in joints:
            topic = f"/{NODE_NAME}/estimate"
            if len(joints) > 1:
                topic = f"/{NODE_NAME}/{joint}/estimate"
            node.create_subscription(Float64MultiArray, topic, _estimate_callback(inbox, joint), 10)
        node.create_subscription(
            DiagnosticArray, "/diagnostics", _diagnostics_callback(inbox, joints), 10
        )
        spinner.start()
        deadline = time.monotonic() + MATCH_TIMEOUT_S
        while not (cmd_pub.get_subscription_count() and comp_sub.get_publisher_count()):
            if node_proc.poll() is not None:
                raise GenBacklashError(_node_failed(node_log, node_proc.returncode))
            if time.monotonic() > deadline:
                raise GenBacklashError(
                    f"the identifier node did not subscribe /command within "
                    f"{MATCH_TIMEOUT_S:g} s (its log: {node_log})"
                )
            time.sleep(0.05)
        log("demo --live: the node is up; the arm starts moving (Ctrl-C stops)")
        result = _run_arm(arm, settings, node, cmd_pub, enc_pub, inbox, log)
        failed = False
        return result
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()
        if node_proc.poll() is None:
            node_proc.send_signal(signal.SIGINT)
            try:
                node_proc.wait(15.0)
            except subprocess.TimeoutExpired:
                node_proc.kill()
                node_proc.wait()
        if failed:
            log(f"demo --live: the node's log is kept in {node_log}")
        else:
            shutil.rmtree(workdir, ignore_errors=True)


def _node_failed(node_log: Path, code: int | None) -> str:
    tail = node_log.read_text(encoding="utf-8", errors="replace").strip().splitlines()[-3:]
    return f"the identifier node exited with status {code}: " + " | ".join(tail)


def _run_arm(
    arm: SimulatedArm,
    settings: ArmSettings,
    node: Any,
    cmd_pub: Any,
    enc_pub: Any,
    inbox: _Inbox,
    log: Callable[[str], None],
) -> LiveResult:
    """The arm's real-time loop: commands at their rate, the physics and the JointState at
    the encoder's, a line a second."""
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Float64MultiArray, MultiArrayDimension

    joints = settings.joints
    enc_ns = round(1e9 / settings.encoder_rate)
    cmd_ns = round(1e9 / settings.command_rate)
    size = len(joints) + 1
    dim = MultiArrayDimension(label="joints,command_number", size=size, stride=size)
    start = time.monotonic_ns()
    behind = 0  # how far the loop fell behind real time at worst, ns
    sent, k = 0, 0
    next_line = 1_000_000_000
    end_ns = arm.commands * cmd_ns
    # Each command period: publish command c at c * cmd_ns; from c * cmd_ns + ANSWER_NS take
    # the latest answer, as a drive's control loop takes the latest command each tick: while
    # the answer to c has not come, step the physics one POLL_NS at a time on what it holds
    # and look again; once it has, step to the next command's first look. Publish the
    # readings of each stretch as real time reaches them.
    events: list[tuple[int, int, int]] = []  # (time, kind, index): 0 command, 1 step, 2 reading
    for c in range(arm.commands):
        events.append((c * cmd_ns, 0, c))
        events.append((c * cmd_ns + ANSWER_NS, 1, c))
    events += [(j * enc_ns, 2, j) for j in range(1, end_ns // enc_ns)]
    heapq.heapify(events)
    arm.step_to(ANSWER_NS)  # before the first answer the arm holds where it stands
    tick = 0
    while events:
        when, kind, index = heapq.heappop(events)
        wait = start + when - time.monotonic_ns()
        if wait > 0:
            time.sleep(wait / 1e9)
        else:
            behind = max(behind, -wait)
        if kind == 0:
            tick = index
            msg = Float64MultiArray()
            msg.layout.dim = [dim]
            msg.data = [*arm.desired(index), float(index)]
            cmd_pub.publish(msg)
            sent += 1
        elif kind == 1:
            with inbox.lock:
                answer, inbox.command = inbox.command, None
            number = -1
            if answer is not None and len(answer) == len(joints) + 1:
                number = int(answer[-1])
                arm.obey(answer[:-1], number)
            next_look = (index + 1) * cmd_ns + ANSWER_NS
            if number < index and when + POLL_NS < next_look:
                arm.step_to(when + POLL_NS)  # the answer to this command is not here yet
                heapq.heappush(events, (when + POLL_NS, 1, index))
            else:
                arm.step_to(next_look)
        else:
            loads = arm.loads_at(when, tick)
            state = JointState()
            # stamped when published, on the clock the node stamps the (headerless) commands
            # by: if the arm falls behind real time, readings and commands stay in order
            state.header.stamp = node.get_clock().now().to_msg()
            state.name = list(joints)
            state.position = list(loads)
            enc_pub.publish(state)
            k += 1
            if when >= next_line:
                _line(arm, inbox, when, log)
                next_line += 1_000_000_000
    time.sleep(0.3)  # the last answers and estimates
    half = arm.second_half()
    with inbox.lock:
        result = LiveResult(
            joints,
            arm.play,
            play=tuple(inbox.play[j] for j in joints),
            compensated_rms=tuple(obeyed for obeyed, _ in half),
            uncompensated_rms=tuple(twin for _, twin in half),
            compensation=tuple(inbox.state[j] for j in joints),
            commands_sent=sent,
            commands_answered=inbox.answered,
            behind_s=behind / 1e9,
            verdicts=tuple(arm.verdicts()),
        )
    _table(result, log)
    return result


def _line(arm: SimulatedArm, inbox: _Inbox, now: int, log: Callable[[str], None]) -> None:
    with inbox.lock:
        play = dict(inbox.play)
        state = dict(inbox.state)
        reason = dict(inbox.reason)
        changed = {j for j in state if state[j] != inbox.shown[j]}
        inbox.shown.update(state)
    parts = []
    for joint, (obeyed, twin) in zip(arm.settings.joints, arm.window(), strict=True):
        said = reason[joint] not in ("", f"compensation {state[joint]}")
        why = f" ({reason[joint]})" if joint in changed and said else ""
        parts.append(
            f"{joint}: play {_mrad(play[joint])} mrad | RMS error last s "
            f"{_mrad(obeyed)} compensated, {_mrad(twin)} uncompensated | "
            f"compensation {state[joint]}{why}"
        )
    log(f"{now / 1e9:5.0f} s  " + "\n         ".join(parts))


def _table(result: LiveResult, log: Callable[[str], None]) -> None:
    log("")
    log(
        f"{'joint':<12}{'play (mrad)':>12}{'geometric':>11}{'RMS err, 2nd half (mrad)':>26}"
        f"{'cut':>7}{'twins':>7}{'acted (s)':>10}{'cut then':>9}  compensation"
    )
    for k, joint in enumerate(result.joints):
        comp, raw = result.compensated_rms[k], result.uncompensated_rms[k]
        cut = 1.0 - comp / raw if raw > 0 else math.nan
        verdict = result.verdicts[k] if k < len(result.verdicts) else None
        spread = f"{verdict.half.spread:.0%}" if verdict else "n/a"
        acted = f"{verdict.acted.seconds:.1f}" if verdict else "n/a"
        then = verdict.acted.cut if verdict else math.nan
        then_text = "n/a" if not math.isfinite(then) else f"{then:.0%}"
        log(
            f"{joint:<12}{_mrad(result.play[k]):>12}{_mrad(result.geometric_play):>11}"
            f"{_mrad(comp) + ' vs ' + _mrad(raw) + ' uncomp.':>26}"
            f"{cut:>7.0%}{spread:>7}{acted:>10}{then_text:>9}  {result.compensation[k]}"
        )
    log(
        f"{result.commands_answered} of {result.commands_sent} commands answered "
        "(the arm obeys only the compensated commands; 'twins': what two uncompensated twins "
        "differ by over the second half; 'acted': readings while compensated commands went "
        "out and 1 s after, and the cut over them)"
    )
    for joint, verdict in zip(result.joints, result.verdicts, strict=False):
        line = verdict.explain(joint)
        if line is not None:
            log(line)
    if result.behind_s > 0.02:
        log(
            f"note: the simulated arm fell behind real time by up to {1e3 * result.behind_s:.0f} "
            "ms (a busy machine): the node then sees late readings, and its numbers suffer"
        )


def main_live(args: Any) -> int:
    """``genbacklash demo --live``: exit 0, or 2 with one line when it cannot run."""
    joints = tuple(f"joint_{k + 1}" for k in range(args.joints))
    try:
        settings = ArmSettings(
            joints=joints,
            variant=args.physics,
            bandwidth=args.bandwidth,
            duration=args.duration,
            encoder_rate=args.encoder_rate,
            seed=args.seed,
        )
        run_live(
            settings,
            transport=args.transport,
            thread_priority=args.thread_priority,
        )
    except GenBacklashError as err:
        print(f"genbacklash demo: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("genbacklash demo: stopped", file=sys.stderr)
        return 0
    return 0
