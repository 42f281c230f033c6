"""``genbacklash export``: the inverse backlash as a lookup table for firmware or a controller.

Registered by :mod:`genbacklash_ros.cli.main` through :func:`add_parser`. MODEL is a node
checkpoint (``identify``/``replay --checkpoint``, or the node's own ``checkpoint_file``) or
identify's ``--json`` output. The table holds, for desired load positions ``x`` over the
model's valid range, the two commands that reach ``x``: approached from below (the lifting
branch inverted, ``R^-1(x)`` for increasing branches: moving up) and from above (the lowering
branch, ``L^-1(x)``: moving down), from :func:`genbacklash_core.inverse.branch_inverse`, the
inversion the compensator (:class:`~genbacklash_core.InverseBacklash`) runs.

The valid range is where both inversions are exact and the model is a backlash: the branches
are monotone (:func:`~genbacklash_core.inverse.invertible_range`) and apart
(:meth:`~genbacklash_core.GeneralBacklash.crossings`) at both commands of every ``x``. For
straight branches (or any that are monotone and apart everywhere) it is unbounded; then
``--range`` must say which positions to table.

Examples
--------
>>> from genbacklash_core import GeneralBacklash
>>> table = inverse_table(GeneralBacklash.ideal(1.0, 0.3, 0.5), 3, (0.0, 1.0))
>>> table.x.tolist(), table.up.tolist(), table.down.round(12).tolist()
([0.0, 0.5, 1.0], [0.5, 1.0, 1.5], [-0.3, 0.2, 0.7])
"""

from __future__ import annotations

import argparse
import json
import math
import re
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from genbacklash_core import Cascade, GenBacklashError, GeneralBacklash
from genbacklash_core.cascade import backlash_of, model_from_dict
from genbacklash_core.inverse import CompensatorOptions, branch_inverse, invertible_range
from genbacklash_ros.node.checkpoint import CheckpointError, checkpoint_from_dict, write_atomic

__all__ = [
    "FORMATS",
    "InverseTable",
    "add_parser",
    "c_header",
    "cmd_export",
    "csv_text",
    "export_paths",
    "inverse_table",
    "read_model",
    "valid_range",
]

FORMATS = ("csv", "c", "both")
DEFAULT_POINTS = 256
MAX_POINTS = 1_000_000
_SUFFIXES = {"csv": (".csv",), "c": (".h",), "both": (".csv", ".h")}
_SEARCH = 1e3  # without a finite end, crossings are sought this many plays (or 1) around
_C_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")

Model = GeneralBacklash | Cascade


# --------------------------------------------------------------------------- the model


def read_model(path: str | Path) -> tuple[Model, str]:
    """The model in ``path`` and what the file was: a node checkpoint, identify's ``--json``
    output (or an object whose ``model`` is one, as replay's ``--json``).

    Raises :class:`GenBacklashError` with a one-line reason for anything else.
    """
    file = Path(path)
    if not file.exists():
        raise GenBacklashError(f"MODEL {file} does not exist")
    if file.is_dir():
        raise GenBacklashError(f"MODEL {file} is a directory; give a checkpoint or JSON file")
    try:
        data = json.loads(file.read_text(encoding="utf-8"))
    except OSError as err:
        raise GenBacklashError(f"cannot read MODEL {file}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise GenBacklashError(f"MODEL {file} is not JSON (not UTF-8 text)") from err
    except json.JSONDecodeError as err:
        raise GenBacklashError(
            f"MODEL {file} is not JSON ({err.msg} at line {err.lineno}); give a node checkpoint "
            "or the output of 'genbacklash identify --json'"
        ) from err
    if isinstance(data, dict) and "format" in data:
        try:
            checkpoint = checkpoint_from_dict(data)
        except CheckpointError as err:
            raise GenBacklashError(f"MODEL {file} is not a usable checkpoint: {err}") from err
        model = checkpoint.estimate.model
        if model is None:
            raise GenBacklashError(
                f"MODEL {file} is a checkpoint without a valid model "
                f"({checkpoint.estimate.state.value}: {checkpoint.estimate.reason})"
            )
        return model, "checkpoint"
    kind = "identify output"
    if isinstance(data, dict) and "backlash" not in data and isinstance(data.get("model"), dict):
        data = data["model"]  # replay --json: the estimate's model in identify's form
        kind = "replay output"
    if not isinstance(data, dict) or "backlash" not in data:
        raise GenBacklashError(
            f"MODEL {file} holds no model: expected a node checkpoint or the output of "
            "'genbacklash identify --json' (an object with a 'backlash' entry)"
        )
    try:
        model = model_from_dict(data)
    except (GenBacklashError, ValueError, KeyError, TypeError) as err:
        what = f"missing {err}" if isinstance(err, KeyError) else str(err)
        raise GenBacklashError(f"MODEL {file}: not a valid model ({what})") from err
    return model, kind


# --------------------------------------------------------------------------- valid range


def _pushing(backlash: GeneralBacklash) -> tuple[str, str]:
    """Names of the branches that push the output up and down (R, L when increasing)."""
    return ("right", "left") if backlash.sign > 0 else ("left", "right")


def _value(backlash: GeneralBacklash, branch: str, u: float) -> float:
    """A branch's value at ``u``; at an infinite ``u`` the limit of a monotone branch."""
    if math.isinf(u):
        return math.copysign(math.inf, u * backlash.sign)
    values = backlash.left(u) if branch == "left" else backlash.right(u)
    return float(np.asarray(values).reshape(-1)[0])


@dataclass(frozen=True)
class ValidRange:
    """Where a model's inverse is exact: commands ``u`` and load positions ``x``.

    ``commands`` is the interval of inputs around the dead zone on which both branches are
    monotone and apart; ``positions`` the load positions both branches reach from inside it.
    An end is infinite where the model sets no limit.
    """

    commands: tuple[float, float]
    positions: tuple[float, float]

    @property
    def bounded(self) -> bool:
        """True when both position ends are finite."""
        return all(math.isfinite(v) for v in self.positions)

    def options(self) -> CompensatorOptions:
        """The compensator options that invert on :attr:`commands` (as the table does)."""
        return CompensatorOptions(valid_range=self.commands)


def valid_range(model: Model) -> ValidRange:
    """The valid range of ``model``'s inverse (see :class:`ValidRange`).

    Around the dead zone (the command halfway between the branches' zero crossings
    ``u = -c_L`` and ``u = c_R``): the monotone parts of both branches
    (:func:`~genbacklash_core.inverse.invertible_range`), cut at the nearest crossings of the
    branches on either side (:meth:`~genbacklash_core.GeneralBacklash.crossings`; where a
    monotone part is unbounded, crossings are sought within 1000 plays of the dead zone).
    """
    backlash = backlash_of(model)
    low, high = invertible_range(backlash)
    anchor = 0.5 * (backlash.c_right - backlash.c_left)
    if not low < anchor < high:
        raise GenBacklashError(
            f"the branches are not monotone at the dead zone (u = {anchor:.6g}); the model "
            "cannot be inverted there"
        )
    reach = _SEARCH * max(1.0, backlash.c_left + backlash.c_right, abs(anchor))
    lo_search = low if math.isfinite(low) else anchor - reach
    hi_search = high if math.isfinite(high) else anchor + reach
    crossings = backlash.crossings(lo_search, hi_search)
    if any(c == anchor for c in crossings) or not _apart(backlash, anchor):
        raise GenBacklashError(
            f"the branches are not apart at the dead zone (u = {anchor:.6g}); the model is no "
            "backlash there"
        )
    low = max([c for c in crossings if c < anchor], default=low)
    high = min([c for c in crossings if c > anchor], default=high)
    up, down = _pushing(backlash)
    ends = []
    for branch in (up, down):
        a, b = _value(backlash, branch, low), _value(backlash, branch, high)
        ends.append((min(a, b), max(a, b)))
    x_low, x_high = max(e[0] for e in ends), min(e[1] for e in ends)
    if not x_low < x_high:
        raise GenBacklashError(
            f"no load position is reached by both branches on the valid commands [{low:.6g}, "
            f"{high:.6g}]"
        )
    return ValidRange((low, high), (x_low, x_high))


def _apart(backlash: GeneralBacklash, u: float) -> bool:
    left, right = backlash.branches_at(u)
    return (left - right) * backlash.sign > 0.0


# --------------------------------------------------------------------------- the table


@dataclass(frozen=True)
class InverseTable:
    """The exported table: positions ``x`` and the commands reaching them moving up/down."""

    model: Model
    x: np.ndarray
    up: np.ndarray
    down: np.ndarray
    valid: ValidRange

    @property
    def range(self) -> tuple[float, float]:
        """The tabled positions' range."""
        return float(self.x[0]), float(self.x[-1])


def _check_range(wanted: tuple[float, float] | None, valid: ValidRange) -> tuple[float, float]:
    x_low, x_high = valid.positions
    shown = f"[{x_low!r}, {x_high!r}]"
    if wanted is None:
        if not valid.bounded:
            raise GenBacklashError(
                f"the model is valid for positions {shown} (its branches are monotone and "
                "apart without end): give --range LO HI, the positions to table (those the "
                "data covered)"
            )
        return x_low, x_high
    low, high = wanted
    if not (math.isfinite(low) and math.isfinite(high)):
        raise GenBacklashError(f"--range needs finite numbers, got {low!r} {high!r}")
    if not low < high:
        raise GenBacklashError(f"--range needs LO < HI, got {low!r} {high!r}")
    slack = 1e-12 * max(1.0, abs(low), abs(high))  # the printed range typed back in
    if low < x_low - slack or high > x_high + slack:
        raise GenBacklashError(
            f"--range {low!r} {high!r} lies outside the valid range {shown} of the model "
            "(where both branches are monotone and apart); choose a range inside it"
        )
    return max(low, x_low), min(high, x_high)


def inverse_table(
    model: Model, points: int = DEFAULT_POINTS, x_range: tuple[float, float] | None = None
) -> InverseTable:
    """The inverse of ``model`` at ``points`` positions evenly spread over ``x_range``
    (default: the whole valid range, which must then be bounded).

    Raises :class:`GenBacklashError` when ``x_range`` leaves the valid range or ``points``
    is below 2.
    """
    if isinstance(points, bool) or not isinstance(points, int) or points < 2:
        raise GenBacklashError(f"--points must be a whole number >= 2, got {points!r}")
    if points > MAX_POINTS:
        raise GenBacklashError(f"--points must be at most {MAX_POINTS}, got {points}")
    valid = valid_range(model)
    low, high = _check_range(x_range, valid)
    x = np.linspace(low, high, points)
    x[0], x[-1] = low, high
    options = valid.options()
    up = branch_inverse(model, x, +1, options)
    down = branch_inverse(model, x, -1, options)
    backlash = backlash_of(model)
    span = (float(min(up.min(), down.min())), float(max(up.max(), down.max())))
    if span[0] < span[1]:
        inside = [c for c in backlash.crossings(*span) if span[0] < c < span[1]]
        if inside:  # beyond the crossing search of valid_range: an unbounded model's far end
            raise GenBacklashError(
                f"the branches cross at u = {inside[0]:.6g}, inside the commands of --range "
                f"{low!r} {high!r}; choose a narrower range"
            )
    return InverseTable(model, x, up, down, valid)


# --------------------------------------------------------------------------- writers


def _number(value: float) -> str:
    """Shortest text that reads back as the same double (Python and C alike)."""
    return repr(float(value))


def csv_text(table: InverseTable) -> str:
    """The table as CSV: a header naming the columns and units, then one row per position."""
    lines = ["x_rad,u_up_rad,u_down_rad"]
    lines += [
        f"{_number(x)},{_number(u)},{_number(d)}"
        for x, u, d in zip(table.x, table.up, table.down, strict=True)
    ]
    return "\n".join(lines) + "\n"


def _model_comment(model: Model) -> list[str]:
    backlash = backlash_of(model)
    lines = [
        f"m_left = {list(backlash.m_left)!r}, c_left = {backlash.c_left!r}",
        f"m_right = {list(backlash.m_right)!r}, c_right = {backlash.c_right!r}",
    ]
    if isinstance(model, Cascade):
        lines.append("(of a cascade: only the backlash is inverted; the linear block is not)")
    return lines


def _array(name: str, values: np.ndarray, count: str) -> str:
    body = ",\n".join(
        "    " + ", ".join(_number(v) for v in values[k : k + 4]) for k in range(0, values.size, 4)
    )
    return f"static const double {name}[{count}] = {{\n{body}\n}};\n"


def c_header(table: InverseTable, name: str = "genbacklash_inverse", source: str = "") -> str:
    """The table as a C header: ``static const`` arrays, the point count and range, and how
    to use them."""
    upper = name.upper()
    low, high = table.range
    count = f"{upper}_POINTS"
    lines = [
        "/* Inverse backlash lookup table, written by 'genbacklash export'"
        + (f" from {source}" if source else "")
        + ".",
        " *",
        " * Model: " + "\n *        ".join(_model_comment(table.model)),
        " *",
        f" * {name}_x[k]      desired load position x (rad), evenly spaced over",
        f" *                  [{upper}_X_MIN, {upper}_X_MAX], {count} points",
        f" * {name}_u_up[k]   command (rad) that reaches x moving up (approached from below)",
        f" * {name}_u_down[k] command (rad) that reaches x moving down (approached from above)",
        " *",
        " * How to use it, each control cycle, for the desired position x:",
        " *   1. Clamp x to [X_MIN, X_MAX]: the model is only valid there.",
        " *   2. Pick the column by the direction of motion: u_up while x rises, u_down while",
        " *      it falls; while x holds, keep the last command.",
        " *   3. Interpolate linearly: s = (x - X_MIN) / (X_MAX - X_MIN) * (POINTS - 1),",
        " *      k = floor(s) (at most POINTS - 2), u = col[k] + (s - k) * (col[k+1] - col[k]).",
        " * At a reversal the command jumps across the play, from one column to the other.",
        " */",
        f"#ifndef {upper}_H",
        f"#define {upper}_H",
        "",
        f"#define {count} {table.x.size}",
        f"#define {upper}_X_MIN {_number(low)}",
        f"#define {upper}_X_MAX {_number(high)}",
        "",
        f"static const unsigned int {name}_points = {count};",
        f"static const double {name}_x_min = {upper}_X_MIN;",
        f"static const double {name}_x_max = {upper}_X_MAX;",
        "",
        _array(f"{name}_x", table.x, count),
        _array(f"{name}_u_up", table.up, count),
        _array(f"{name}_u_down", table.down, count),
        f"#endif /* {upper}_H */",
        "",
    ]
    return "\n".join(lines)


def export_paths(output: str | Path, fmt: str) -> list[Path]:
    """The files ``-o OUTPUT`` stands for: OUTPUT with its suffix set to ``.csv``, ``.h``."""
    base = Path(output)
    if base.name in ("", ".", "..") or base.is_dir():
        raise GenBacklashError(
            f"-o {output} is a directory; give a file name (OUT.csv and OUT.h are written)"
        )
    return [base.with_suffix(suffix) for suffix in _SUFFIXES[fmt]]


# --------------------------------------------------------------------------- command


def _points(text: str) -> int:
    """``--points`` (checked here, not by argparse: one line on stderr, as every bad input)."""
    try:
        value = int(text)
    except ValueError:
        raise GenBacklashError(f"--points must be a whole number >= 2, got {text!r}") from None
    if not 2 <= value <= MAX_POINTS:
        raise GenBacklashError(f"--points must be a whole number in [2, {MAX_POINTS}], got {value}")
    return value


def _range(texts: list[str] | None) -> tuple[float, float] | None:
    if texts is None:
        return None
    try:
        low, high = (float(t) for t in texts)
    except ValueError:
        raise GenBacklashError(f"--range needs two numbers LO HI, got {' '.join(texts)}") from None
    return low, high


def cmd_export(args: argparse.Namespace) -> int:
    """Run ``genbacklash export``."""
    if not _C_NAME.fullmatch(args.name):
        raise GenBacklashError(f"--name must be a C identifier, got {args.name!r}")
    paths = export_paths(args.output, args.format)
    points = _points(args.points)
    x_range = _range(args.range)
    model, kind = read_model(args.model)
    table = inverse_table(model, points, x_range)
    source = Path(args.model).name
    texts = {".csv": csv_text(table), ".h": c_header(table, args.name, source)}
    written = []
    for path in paths:
        try:
            write_atomic(path, texts[path.suffix])
        except OSError as err:
            raise GenBacklashError(f"cannot write {path}: {err.strerror or err}") from err
        written.append(str(path))
    low, high = table.range
    x_low, x_high = table.valid.positions
    print(
        f"wrote {', '.join(written)}: {table.x.size} points over x in [{low:.6g}, {high:.6g}] "
        f"rad (valid range [{x_low:.6g}, {x_high:.6g}]) from the {kind} {args.model}",
        file=sys.stderr,
    )
    return 0


_DESCRIPTION = """\
Write the inverse backlash of a model as a lookup table for firmware or a ros2_control
controller: for desired load positions x over the model's valid range, the command that
reaches x moving up (approached from below: the lower branch inverted, R^-1(x) for
increasing branches) and the one that reaches x moving down (from above: L^-1(x)). These are
the commands the node's compensator sends (genbacklash_core.inverse.branch_inverse).

MODEL is a node checkpoint (written by 'identify --checkpoint', 'replay --checkpoint' or the
node's checkpoint_file) or the output of 'genbacklash identify --json'. Of a cascade only the
backlash is inverted.

The valid range is where both branches are monotone and apart (the model is a backlash
there): outside it the table would be wrong, so it is never extended past it. Straight
branches (an ideal backlash) are valid for every position: then give --range, the positions
the data covered. The CSV has the columns x_rad, u_up_rad, u_down_rad (rad, or the unit of
the data the model came from); the C header (.h) has static const double arrays
<name>_x, <name>_u_up, <name>_u_down, the point count and the range, and a comment on how to
use them: pick the up or down column by the direction of motion, interpolate linearly,
clamp x to the range. Exit status 2 with one line on bad input.
"""

_EPILOG = """\
examples:
  genbacklash identify run.csv --checkpoint start.json
  genbacklash export start.json -o joint1            # joint1.csv and joint1.h
  genbacklash identify run.csv --json > model.json
  genbacklash export model.json -o table.h --format c --points 512 --range -1.5 1.5
"""


def add_parser(subparsers: argparse._SubParsersAction[Any]) -> None:
    """Register ``export`` on the ``genbacklash`` command line."""
    parser = subparsers.add_parser(
        "export",
        help="write the inverse backlash as a lookup table (CSV, C header) with its valid range",
        description=_DESCRIPTION,
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        "model",
        metavar="MODEL",
        help="a node checkpoint (identify/replay --checkpoint) or identify's --json output",
    )
    parser.add_argument(
        "-o",
        "--output",
        required=True,
        metavar="OUT",
        help="output file; its suffix is set by the format: OUT.csv, OUT.h, or both",
    )
    parser.add_argument(
        "--format",
        choices=FORMATS,
        default="both",
        help="csv, c (a C header) or both (default both)",
    )
    parser.add_argument(
        "--points",
        default=str(DEFAULT_POINTS),
        metavar="N",
        help=f"table points, evenly spaced over the range, >= 2 (default {DEFAULT_POINTS})",
    )
    parser.add_argument(
        "--range",
        nargs=2,
        metavar=("LO", "HI"),
        default=None,
        help="load positions to table, rad, inside the valid range (default: the valid range; "
        "required when the model sets no bound)",
    )
    parser.add_argument(
        "--name",
        default="genbacklash_inverse",
        help="C: prefix of the arrays and macros (default genbacklash_inverse)",
    )
    parser.set_defaults(func=cmd_export)
