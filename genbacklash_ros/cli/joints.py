"""Several joints from one bag: ``--joint a --joint b`` (or ``--joint a,b``) on replay,
identify and diagnose.

:class:`ListOption` makes ``--joint`` and ``--command-index`` repeatable (commas allowed);
:func:`per_joint` wraps a command: with at most one joint it runs as it always did; with
several it checks the whole selection against the bag first (a joint the bag lacks stops
before any work), then runs the command once per joint -- the same code, the joint's own
selection -- and gathers the results: ``--json`` prints one object keyed by joint, the text
output has a heading per joint, each output directory (``-o``, ``--report``, ``--plot``)
gets a sub-directory per joint, and a ``--checkpoint FILE`` must hold ``{joint}``. The exit
status is the worst of the joints' (2 bad input, 3 not converged, 0 all well).
"""

from __future__ import annotations

import argparse
import contextlib
import html
import io
import json
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from genbacklash_core import GenBacklashError

__all__ = ["ListOption", "per_joint", "selection"]

Command = Callable[[argparse.Namespace], int]


class ListOption(argparse.Action):
    """A repeatable option whose values may also be comma-separated: ``--joint a --joint
    b,c`` -> ``["a", "b", "c"]`` (``type`` converts each item)."""

    def __init__(self, option_strings: Sequence[str], dest: str, **kwargs: Any) -> None:
        self._convert: Callable[[str], Any] = kwargs.pop("type", None) or str
        super().__init__(option_strings, dest, **kwargs)

    def __call__(
        self,
        parser: argparse.ArgumentParser,
        namespace: argparse.Namespace,
        values: str | Sequence[Any] | None,
        option_string: str | None = None,
    ) -> None:
        items = list(getattr(namespace, self.dest, None) or [])
        for part in str(values).split(","):
            part = part.strip()
            if not part:
                continue
            try:
                items.append(self._convert(part))
            except ValueError:
                parser.error(f"argument {option_string}: invalid value {part!r}")
        setattr(namespace, self.dest, items)


def selection(args: argparse.Namespace) -> tuple[list[str], list[int]]:
    """The joints and command indices a command line selects (lists, maybe empty)."""
    joints = (
        args.joint if isinstance(args.joint, list) else [] if args.joint is None else [args.joint]
    )
    indices = args.command_index
    indices = indices if isinstance(indices, list) else [] if indices is None else [indices]
    return list(joints), list(indices)


def per_joint(
    func: Command,
    *,
    data: str,
    dirs: Sequence[str] = (),
    files: Sequence[str] = (),
    report: str | None = None,
) -> Command:
    """``func`` for one joint or several (see the module notes).

    Parameters
    ----------
    func : callable
        The command (one joint: ``args.joint`` a name or None, ``args.command_index`` an
        int or None).
    data : str
        The attribute holding the input (a bag, or a CSV for identify and diagnose).
    dirs : sequence of str
        Output directories: ``<dir>/<joint>`` per joint.
    files : sequence of str
        Output files: must hold ``{joint}``, replaced by each joint's name.
    report : str, optional
        The attribute of a report directory that also gets an ``index.html`` linking to the
        joints' reports.
    """

    def run(args: argparse.Namespace) -> int:
        joints, indices = selection(args)
        if len(joints) <= 1 and len(indices) <= 1:
            args.joint = joints[0] if joints else None
            args.command_index = indices[0] if indices else None
            return func(args)
        _check(args, joints, indices, data, files)
        codes: list[int] = []
        gathered: dict[str, object] = {}
        for k, joint in enumerate(joints):
            one = argparse.Namespace(**vars(args))
            one.joint = joint
            one.command_index = indices[k] if indices else None
            for name in dirs:
                value = getattr(args, name, None)
                if value:
                    Path(value).mkdir(parents=True, exist_ok=True)
                    setattr(one, name, str(Path(value) / joint))
            for name in files:
                value = getattr(args, name, None)
                if value:
                    setattr(one, name, str(value).replace("{joint}", joint))
            if getattr(args, "json", False):
                out = io.StringIO()
                with contextlib.redirect_stdout(out):
                    codes.append(func(one))
                text = out.getvalue().strip()
                gathered[joint] = json.loads(text) if text else None
            else:
                print(f"== joint {joint} ==", flush=True)
                codes.append(func(one))
                print(flush=True)
        if getattr(args, "json", False):
            print(json.dumps(gathered))
        if report and getattr(args, report, None):
            _index(Path(getattr(args, report)), joints, str(args.command))
        return max(codes)

    run.__doc__ = func.__doc__
    return run


def _check(
    args: argparse.Namespace,
    joints: list[str],
    indices: list[int],
    data: str,
    files: Sequence[str],
) -> None:
    """The whole selection, before any work."""
    if len(joints) < 2:
        raise GenBacklashError(
            "several --command-index need as many --joint (each joint's name in the "
            "encoder's JointState)"
        )
    if len(set(joints)) != len(joints):
        raise GenBacklashError(f"--joint lists a joint twice: {', '.join(joints)}")
    if indices and len(indices) != len(joints):
        raise GenBacklashError(
            f"give one --command-index per --joint, in the same order: {len(joints)} joints, "
            f"{len(indices)} indices"
        )
    for name in files:
        value = getattr(args, name, None)
        if value and "{joint}" not in str(value):
            option = "--" + name.replace("_", "-")
            raise GenBacklashError(
                f"{option} {value}: with several joints the file name must hold '{{joint}}' "
                "(replaced by each joint's name)"
            )
    source = str(getattr(args, data))
    from genbacklash_ros.cli.bag_input import is_bag

    if not is_bag(source):
        raise GenBacklashError(f"several --joint need a bag, not {source}")
    command_topic = getattr(args, "command_topic", None)
    encoder_topic = getattr(args, "encoder_topic", None)
    if not command_topic or not encoder_topic:
        raise GenBacklashError("a bag needs --command TOPIC and --encoder TOPIC")
    from genbacklash_ros.bags.bagio import BagReader, check_selection
    from genbacklash_ros.node.messages import Float64MultiArray

    with BagReader(source) as reader:
        for k, joint in enumerate(joints):
            index = indices[k] if indices else 0
            cmd, _ = check_selection(
                reader, command_topic, encoder_topic, joint=joint, command_index=index
            )
            if cmd.msgtype == Float64MultiArray.ros_type and not indices:
                raise GenBacklashError(
                    f"the command {command_topic} is a Float64MultiArray: give each joint's "
                    "element with --command-index, one per --joint in the same order"
                )


def _index(root: Path, joints: list[str], command: str) -> None:
    """``root/index.html``: a link to each joint's report."""
    items = "\n".join(
        f'<li><a href="{html.escape(j)}/index.html">{html.escape(j)}</a></li>' for j in joints
    )
    root.mkdir(parents=True, exist_ok=True)
    (root / "index.html").write_text(
        f"<!doctype html><meta charset='utf-8'><title>genbacklash {command}: "
        f"{len(joints)} joints</title><h1>genbacklash {command}: one report per joint</h1>"
        f"<ul>\n{items}\n</ul>\n",
        encoding="utf-8",
    )
    print(f"wrote {root / 'index.html'}", file=sys.stderr)
