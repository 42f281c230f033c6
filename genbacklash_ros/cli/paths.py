"""Every command's input and output paths, checked once before its work starts.

No command may delete or overwrite a path that is one of its inputs, contains one or lies
inside one (a replay whose ``-o`` is its own input bag would otherwise remove the recording);
every output must be writable before hours of work are spent on it; and ``--overwrite``
removes only a bag that genbacklash itself wrote (:data:`OUTPUT_MARKER` inside it), nothing
else. :func:`check_paths` applies the table :data:`COMMAND_PATHS` to a parsed command line;
``genbacklash``'s ``main`` calls it for every command before the command runs.

Examples
--------
>>> import argparse, tempfile
>>> from pathlib import Path
>>> root = Path(tempfile.mkdtemp())
>>> (root / "run").mkdir()
>>> args = argparse.Namespace(
...     command="replay", bag=str(root / "run"), output=str(root / "run"), report=None,
...     params_file=None, overwrite=True)
>>> try:
...     check_paths(args)
... except OutputPathError as err:
...     print(str(err).split(";")[0].replace(str(root), "ROOT"))
-o ROOT/run is the input BAG ROOT/run
"""

from __future__ import annotations

import argparse
import os
import shutil
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from genbacklash_core import GenBacklashError
from genbacklash_ros.bags.output_marker import OUTPUT_MARKER

__all__ = [
    "COMMAND_PATHS",
    "CommandPaths",
    "OutputPathError",
    "PathOption",
    "check_paths",
    "remove_own_output",
]


class OutputPathError(GenBacklashError):
    """An output path that would destroy an input, or that cannot be written."""


@dataclass(frozen=True)
class PathOption:
    """One path-valued option of a command.

    Attributes
    ----------
    attribute : str
        The argparse destination (``args.<attribute>``).
    label : str
        How the user spelt it (``-o``, ``--report``, ``BAG``), for messages.
    kind : str
        ``"input"`` (read only), ``"bag"`` (a new bag directory, replaced only with
        ``--overwrite`` when genbacklash wrote it), ``"dir"`` (a directory files are written
        into, created up front) or ``"file"`` (one file, its directory created up front).
    """

    attribute: str
    label: str
    kind: str


@dataclass(frozen=True)
class CommandPaths:
    """A command's path options: what it reads and what it writes."""

    options: tuple[PathOption, ...]


def _opts(*items: tuple[str, str, str]) -> CommandPaths:
    return CommandPaths(tuple(PathOption(*item) for item in items))


_PARAMS = ("params_file", "--params-file", "input")
_CHECKPOINT = ("checkpoint", "--checkpoint", "file")

#: Each command's path options (commands not listed read and write no paths).
COMMAND_PATHS: dict[str, CommandPaths] = {
    "replay": _opts(
        ("bag", "BAG", "input"),
        _PARAMS,
        ("output", "-o", "bag"),
        ("report", "--report", "dir"),
        _CHECKPOINT,
    ),
    "identify": _opts(("data", "DATA", "input"), _PARAMS, ("plot", "--plot", "dir"), _CHECKPOINT),
    "export": _opts(("model", "MODEL", "input"), ("output", "-o", "file")),
    "readings": _opts(("bag", "BAG", "input"), _PARAMS, ("output", "-o", "file")),
    "diagnose": _opts(
        ("data", "DATA", "input"),
        _PARAMS,
        ("start", "--start", "input"),
        ("report", "--report", "dir"),
    ),
    "simulate": _opts(("output", "-o", "file"), ("bag", "--bag", "bag")),
    "excite": _opts(("output", "-o", "file"), ("bag", "--bag", "bag"), ("plot", "--plot", "file")),
    "demo": _opts(("out", "--out", "dir")),
    "fleet": _opts(("archive", "ARCHIVE", "input"), _PARAMS, ("db", "--db", "file")),
    "fleet-report": _opts(("db", "DB", "input"), ("output", "-o", "dir")),
    "node": _opts(_PARAMS),
}


def _real(path: str | Path) -> Path:
    """The path with links and ``..`` resolved (it need not exist)."""
    return Path(os.path.realpath(os.path.expanduser(str(path))))


def _inside(inner: Path, outer: Path) -> bool:
    """Whether ``inner`` is ``outer`` or lies below it (both resolved)."""
    return inner == outer or outer in inner.parents


def _same(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def _sqlite_file(value: str) -> str | None:
    """The file behind a ``--db`` value (a path or an SQLite URL), or None for a server."""
    if "://" not in value:
        return value
    if value.startswith("sqlite:///"):
        path = value.removeprefix("sqlite:///")
        return None if path in ("", ":memory:") else path
    return None


def _values(args: argparse.Namespace, option: PathOption) -> Iterator[str]:
    value = getattr(args, option.attribute, None)
    if value is None or value == "":
        return
    if option.attribute == "db" and option.kind == "file":
        value = _sqlite_file(str(value))
        if value is None:
            return
    if option.attribute == "start" and not Path(str(value)).exists():
        return  # diagnose --start degree=3: a structure, not a file
    if getattr(args, "command", None) == "export" and option.attribute == "output":
        from genbacklash_ros.cli.export import export_paths

        # -o OUT stands for OUT.csv and/or OUT.h: check the files that are written
        yield from (str(path) for path in export_paths(str(value), args.format))
        return
    yield str(value)


def _conflict(output: Path, inputs: list[tuple[str, str, Path]]) -> str | None:
    for label, given, real in inputs:
        if _inside(output, real) or _same(output, real):
            relation = "is" if output == real or _same(output, real) else "lies inside"
            return f"{relation} the input {label} {given}"
        if _inside(real, output):
            return f"contains the input {label} {given}"
    return None


def _creatable_directory(label: str, given: str, path: Path) -> None:
    """Create the directory ``path`` (and its parents) now, or say why it cannot be."""
    if path.exists() and not path.is_dir():
        raise OutputPathError(
            f"{label} {given} exists and is not a directory; choose a directory for {label}"
        )
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".genbacklash-write-test-{os.getpid()}"
        probe.touch()
        probe.unlink()
    except OSError as err:
        reason = err.strerror or type(err).__name__
        raise OutputPathError(
            f"{label} {given}: cannot write there ({reason}); choose another {label}"
        ) from err


def _check_bag(label: str, given: str, path: Path, overwrite: bool) -> None:
    if path.exists() or path.is_symlink():
        if not overwrite:
            raise OutputPathError(
                f"{label} {given} exists already; choose another {label}, or add --overwrite "
                "to replace a bag an earlier genbacklash run wrote there"
            )
        reason = _not_own_output(path)
        if reason:
            raise OutputPathError(
                f"--overwrite: {given} {reason}; not removing it (remove it yourself if it is "
                f"yours to lose, or choose another {label})"
            )
    _creatable_directory(label, given, path.parent)


def _not_own_output(path: Path) -> str | None:
    """Why ``path`` is not a bag directory genbacklash wrote (None: it is one)."""
    if path.is_symlink() or not path.is_dir():
        return "is not a bag directory genbacklash wrote"
    if not (path / OUTPUT_MARKER).is_file():
        return f"has no {OUTPUT_MARKER}, so genbacklash did not write it"
    for child in path.iterdir():
        if child.is_dir() or child.is_symlink():
            return f"holds {child.name}/, which genbacklash did not write"
        if child.name not in (OUTPUT_MARKER, "metadata.yaml") and child.suffix != ".mcap":
            return f"holds {child.name}, which genbacklash did not write"
    return None


def check_paths(args: argparse.Namespace) -> None:
    """Check a parsed command line's paths before its work starts.

    Refuses (:class:`OutputPathError`, a one-line reason) an output that is an input,
    contains one or lies inside one; an output bag that exists, unless ``--overwrite`` is
    given and genbacklash wrote it (which is then removed); an output directory or file's
    directory that cannot be created or written. Creates output directories up front.
    """
    table = COMMAND_PATHS.get(getattr(args, "command", "") or "")
    if table is None:
        return
    inputs = [
        (option.label, value, _real(value))
        for option in table.options
        if option.kind == "input"
        for value in _values(args, option)
    ]
    outputs = [
        (option, value, _real(value))
        for option in table.options
        if option.kind != "input"
        for value in _values(args, option)
    ]
    for option, value, real in outputs:
        clash = _conflict(real, inputs)
        if clash:
            raise OutputPathError(
                f"{option.label} {value} {clash}; choose a path for {option.label} outside "
                "every input (nothing was written)"
            )
    overwrite = bool(getattr(args, "overwrite", False))
    joints = _several_joints(args)
    for option, value, real in outputs:
        if option.kind == "bag" and joints:
            _check_joint_bags(option.label, value, real, joints, overwrite)
        elif option.kind == "bag":
            _check_bag(option.label, value, real, overwrite)
        elif option.kind == "dir":
            _creatable_directory(option.label, value, real)
        elif real.is_dir():
            raise OutputPathError(
                f"{option.label} {value} is a directory; give a file name for {option.label}"
            )
        else:
            _creatable_directory(option.label, value, real.parent)
    for option, _value, real in outputs:
        if option.kind != "bag" or not overwrite:
            continue
        for bag in [real / joint for joint in joints] if joints else [real]:
            if bag.exists() or bag.is_symlink():
                remove_own_output(bag)


def _several_joints(args: argparse.Namespace) -> list[str]:
    """The joints of a command run once per joint (several ``--joint``:
    :func:`genbacklash_ros.cli.joints.per_joint`), whose output bag ``OUT`` is then a
    directory holding one bag per joint, ``OUT/<joint>``; [] for one joint."""
    if not hasattr(args, "joint"):
        return []
    from genbacklash_ros.cli.joints import selection

    joints, _ = selection(args)
    return joints if len(joints) > 1 else []


def _check_joint_bags(
    label: str, given: str, path: Path, joints: list[str], overwrite: bool
) -> None:
    """``path`` holds one bag per joint: each ``path/<joint>`` is checked as an output bag
    (replaced with ``--overwrite`` only when genbacklash wrote it); ``path`` itself is a
    directory that is kept, with whatever else it holds."""
    if path.is_symlink() or (path.exists() and not path.is_dir()):
        raise OutputPathError(
            f"{label} {given} is not a directory; with several --joint, {label} is a "
            "directory that gets a bag per joint"
        )
    for joint in joints:
        _check_bag(label, f"{given}/{joint}", path / joint, overwrite)


def remove_own_output(path: str | Path) -> None:
    """Remove a bag directory genbacklash wrote; refuse (:class:`OutputPathError`) anything
    else."""
    target = Path(path)
    reason = _not_own_output(target)
    if reason:
        raise OutputPathError(f"--overwrite: {target} {reason}; not removing it")
    shutil.rmtree(target)
