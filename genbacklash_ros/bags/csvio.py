"""Reading and writing input/output series as CSV with a header (``u,y`` and optional ``t``).

A ``t`` column gives the record its sample rule (:mod:`genbacklash_core.samples`): a row
that is not one nominal period (the median difference of ``t``, rounded) after the row
before it -- a lost sample, a gap -- breaks the chain of consecutive samples, so that
``identify`` and ``diagnose`` never form a regression row across it. ``t`` may be in seconds
or in integer nanoseconds: a median step of 1000 or more is read as nanoseconds (integer
cells exactly, also beyond 2**53), else as seconds. Without ``t`` every row follows the one
before it.

With increasing stamps the rows go through the same rules as a bag's readings
(:func:`~genbacklash_ros.node.sample_rule.select_rows`: the servo's settling rule and lost
readings bridged along monotone commands, as ``settle_ns`` and ``bridge`` say), each row
being one encoder reading and the command it holds: a CSV of a bag's readings
(``genbacklash readings``, :func:`write_readings_csv`) gives identify and diagnose the bag's
rows, so the same answer.
"""

from __future__ import annotations

import csv
import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import numpy.typing as npt

from genbacklash_core import GenBacklashError
from genbacklash_core.measured import OfflineBaseline
from genbacklash_core.servo import ServoFit, ServoModel
from genbacklash_ros.node.sample_rule import ServoChoice, select_rows, time_breaks

__all__ = [
    "BadRows",
    "Series",
    "dropped_note",
    "read_series_csv",
    "stamps_ns",
    "write_readings_csv",
    "write_series_csv",
]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Series:
    """An input/output record: command ``u``, measured output ``y``, optional time ``t`` [s].

    :func:`read_series_csv` gives ``t`` as the file holds it, except stamps in nanoseconds
    that increase: those become seconds from the first row kept, as a bag's series.

    ``breaks`` (optional, bool): the sample rule, True where a sample does not follow the
    one before it on the encoder's clock (None: all do); for the identifiers' ``breaks``.
    ``dropped``: the line numbers of the file's rows :func:`read_series_csv` left out.
    ``servo``, ``servo_fit``: the servo model whose output ``u`` is, and its estimate
    (:func:`~genbacklash_ros.node.sample_rule.select_rows`; None: ``u`` is the command).
    ``baseline``: the record's tracking without compensation as the node's judge measures
    it (a bag without a node's outputs; None otherwise, and for a CSV, which cannot tell).
    """

    u: FloatArray
    y: FloatArray
    t: FloatArray | None = None
    breaks: npt.NDArray[np.bool_] | None = None
    dropped: tuple[int, ...] = ()
    servo: ServoModel | None = None
    servo_fit: ServoFit | None = None
    baseline: OfflineBaseline | None = None

    def sample_period(self) -> float | None:
        """The nominal sample period in seconds: the median step of ``t`` (None without
        ``t`` or without two increasing stamps). ``t`` is read as seconds, or as integer
        nanoseconds when its median step is 1000 or more (no drivetrain is sampled that
        slowly in seconds).

        >>> Series(u=np.zeros(3), y=np.zeros(3), t=np.array([0.0, 0.002, 0.004])).sample_period()
        0.002
        >>> Series(u=np.zeros(3), y=np.zeros(3), t=np.array([0, 1e6, 2e6])).sample_period()
        0.001
        """
        if self.t is None:
            return None
        t = np.asarray(self.t, dtype=np.float64)
        steps = np.diff(t[np.isfinite(t)])
        steps = steps[steps > 0]
        if not steps.size:
            return None
        step = float(np.median(steps))
        return step / 1e9 if step >= 1000.0 else step


_NS_STEP = 1000.0  # a median step of this or more: the stamps are nanoseconds


def _in_ns(t: npt.ArrayLike) -> bool:
    """Whether stamps ``t`` read as nanoseconds (a median positive step of 1000 or more)."""
    steps = np.diff(np.asarray(t, dtype=np.float64))
    positive = steps[steps > 0]
    return bool(positive.size) and float(np.median(positive)) >= _NS_STEP


def stamps_ns(t: npt.ArrayLike) -> npt.NDArray[np.int64] | None:
    """The stamps ``t`` (seconds, or nanoseconds when the median step is 1000 or more, as
    :meth:`Series.sample_period` reads them) as int64 nanoseconds; None unless every stamp
    is finite and each is after the one before (the rows' rules need a clock).

    >>> stamps_ns([0.0, 0.001, 0.0025]).tolist(), stamps_ns([5, 1_000_005]).tolist()
    ([0, 1000000, 2500000], [5, 1000005])
    >>> stamps_ns([0.0, 0.002, 0.001]) is None
    True
    """
    raw = np.asarray(t)
    if raw.ndim != 1 or raw.size == 0:
        return None
    if np.issubdtype(raw.dtype, np.integer):
        out = raw.astype(np.int64)
    else:
        tt = np.asarray(raw, dtype=np.float64)
        if not np.isfinite(tt).all():
            return None
        if _in_ns(tt):
            out = np.rint(tt).astype(np.int64)
        else:
            out = np.rint((tt - tt[0]) * 1e9).astype(np.int64)  # relative: exact in float64
    if out.size > 1 and not bool((np.diff(out) > 0).all()):
        return None
    return out


BadRows = Literal["raise", "drop", "nan"]
"""What :func:`read_series_csv` does with a row it cannot use (see there)."""

_MAX_LISTED = 8  # line numbers named in a message, at most


def _lines(numbers: Sequence[int]) -> str:
    """``'5, 9 and 12'`` / ``'5, 9, ... (20 in all)'``: line numbers for a message."""
    shown = [str(n) for n in numbers[:_MAX_LISTED]]
    if len(numbers) > _MAX_LISTED:
        return f"{', '.join(shown)}, ... ({len(numbers)} in all)"
    if len(shown) > 1:
        return f"{', '.join(shown[:-1])} and {shown[-1]}"
    return shown[0]


def _number(cell: str) -> tuple[float, str]:
    """The value of a cell and what is wrong with it (``""``: nothing)."""
    text = cell.strip()
    if not text:
        return math.nan, "is empty"
    try:
        value = float(text)
    except ValueError:
        return math.nan, f"{text[:40]!r} is not a number"
    if not math.isfinite(value):
        return value, f"{text[:40]!r} is not finite"
    return value, ""


def _read_rows(
    file: Path, wanted: list[int], names: list[str], bad_rows: BadRows
) -> tuple[np.ndarray, tuple[int, ...], list[int]]:
    """Every data row's ``wanted`` cells, checked one by one (the slow path: a file whose
    fast read failed or held a value that is not finite). Returns the table, the line
    numbers of the rows dropped, and the line number of each row kept."""
    rows: list[list[float]] = []
    kept: list[int] = []
    dropped: list[int] = []
    first_problem = ""
    need = max(wanted) + 1
    with file.open(newline="") as handle:
        reader = csv.reader(handle)
        next(reader, None)  # the header
        for cells in reader:
            line = reader.line_num
            if not cells or cells[0].lstrip().startswith("#"):
                continue  # a blank line or a comment, as numpy's reader skips them
            problem = ""
            if len(cells) < need:
                values = [math.nan] * len(wanted)
                problem = (
                    f"line {line} of {file} has {len(cells)} cell"
                    f"{'' if len(cells) == 1 else 's'}, too few for the columns "
                    f"{', '.join(names[k] for k in wanted)}"
                )
            else:
                values = []
                for k in wanted:
                    value, wrong = _number(cells[k])
                    values.append(value)
                    if wrong and not problem:
                        problem = f"line {line} of {file}, column {names[k]!r}: {wrong}"
            if problem:
                first_problem = first_problem or problem
                if bad_rows != "nan":
                    dropped.append(line)
                    continue
            rows.append(values)
            kept.append(line)
    if dropped and bad_rows == "raise":
        more = ""
        if len(dropped) > 1:
            more = f" ({len(dropped)} rows are bad: lines {_lines(dropped)})"
        raise GenBacklashError(
            f"{first_problem}{more}; fix the file or pass --drop-nonfinite to drop such rows"
        )
    table = np.array(rows, dtype=np.float64).reshape(len(rows), len(wanted))
    return table, tuple(dropped), kept


def dropped_note(path: str | Path, dropped: Sequence[int]) -> str:
    """One line saying which rows of ``path`` :func:`read_series_csv` dropped ("": none).

    >>> dropped_note("d.csv", [3, 7])
    'dropped 2 rows of d.csv that do not hold a finite number in every column used: lines 3 and 7'
    """
    if not dropped:
        return ""
    n = len(dropped)
    return (
        f"dropped {n} row{'' if n == 1 else 's'} of {path} that do"
        f"{'es' if n == 1 else ''} not hold a finite number in every column used: "
        f"line{'' if n == 1 else 's'} {_lines(dropped)}"
    )


def read_series_csv(
    path: str | Path,
    *,
    bad_rows: BadRows = "raise",
    bridge: bool = False,
    settle_ns: int = 0,
    servo: ServoChoice = None,
) -> Series:
    r"""Read a CSV whose header names the columns ``u`` and ``y`` (and optionally ``t``).

    A column ``motor`` in place of ``u`` is a motor encoder's reading, the gear's input
    (the node's ``gear_input`` motor_encoder; ``genbacklash readings --motor-encoder``
    writes one): it is the series' ``u``, each row's motor reading is its own (a reading
    whose motor reading was lost is not a row: its stamp is missing, as a lost reading's),
    and the settling rule does not apply.

    With ``t`` the series carries its ``breaks`` (see the module notes); with increasing
    stamps the rows are chosen by :func:`~genbacklash_ros.node.sample_rule.select_rows`
    (``bridge``: a backlash alone; ``settle_ns``: the servo's settling time, with ``bridge``;
    ``servo``: the servo model or ``"auto"``, which needs ``t``), as a bag's readings are.
    Other columns are ignored, and so are blank lines and lines starting with ``#``.

    A row that cannot be used -- a cell that is empty, not a number, NaN or infinite, or a
    row with too few cells -- is, by ``bad_rows``:

    * ``"raise"``: a :class:`~genbacklash_core.GenBacklashError` naming the file's line
      number (the header is line 1), the column and what is wrong;
    * ``"drop"``: left out; :attr:`Series.dropped` holds the line numbers of the rows left
      out, and the row after each gap breaks the chain of consecutive samples (``breaks``);
    * ``"nan"``: kept with NaN in its cells, for the caller to deal with.

    >>> import tempfile
    >>> file = Path(tempfile.mkdtemp()) / "d.csv"
    >>> _ = file.write_text("u,y\n1,2\nabc,3\n4,5\n")
    >>> read_series_csv(file)
    Traceback (most recent call last):
    ...
    genbacklash_core.errors.GenBacklashError: line 3 of ... column 'u': 'abc' is not a number; ...
    >>> s = read_series_csv(file, bad_rows="drop")
    >>> s.u.tolist(), s.dropped, s.breaks.tolist()
    ([1.0, 4.0], (3,), [False, True])
    """
    if bad_rows not in ("raise", "drop", "nan"):
        raise GenBacklashError(f"bad_rows must be 'raise', 'drop' or 'nan', got {bad_rows!r}")
    file = Path(path)
    try:
        with file.open(newline="") as handle:
            header = next(csv.reader(handle), None)
    except OSError as err:
        raise GenBacklashError(f"cannot read {file}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise GenBacklashError(f"{file} is not a text CSV file: {err}") from err
    except csv.Error as err:
        raise GenBacklashError(f"{file} is not a CSV file: {err}") from err
    if not header:
        raise GenBacklashError(f"{file} is empty; expected a header line with columns u,y")
    names = [name.strip().lower() for name in header]
    motor = "motor" in names and "u" not in names  # a motor encoder's reading as the input
    first = "motor" if motor else "u"
    missing = [c for c in (first, "y") if c not in names]
    if missing:
        raise GenBacklashError(
            f"{file} has columns {header}; the header must name 'u' and 'y' (missing: "
            f"{missing}); a motor encoder's reading may be named 'motor' in place of 'u'"
        )
    wanted = [names.index(first), names.index("y")]
    wanted += [names.index("t")] if "t" in names else []
    dropped: tuple[int, ...] = ()
    kept: list[int] | None = None
    exact_t: npt.NDArray[np.int64] | None = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "no data": reported below instead
            table = np.loadtxt(file, delimiter=",", skiprows=1, usecols=wanted, ndmin=2)
        fast = bool(np.isfinite(table).all())
        if fast and len(wanted) == 3:
            exact_t = _integer_column(file, wanted[2], table.shape[0])
    except (ValueError, IndexError):
        fast = False  # a cell that is not a number, a short row: read row by row below
    except UnicodeDecodeError as err:
        raise GenBacklashError(f"{file} is not a text CSV file: {err}") from err
    if not fast:
        try:
            table, dropped, kept = _read_rows(file, wanted, names, bad_rows)
        except UnicodeDecodeError as err:
            raise GenBacklashError(f"{file} is not a text CSV file: {err}") from err
        except csv.Error as err:
            raise GenBacklashError(f"{file} is not a CSV file: {err}") from err
    if table.shape[0] == 0:
        if dropped:
            raise GenBacklashError(
                f"{file}: every data row was dropped (lines {_lines(dropped)}): none holds "
                f"numbers in all of {', '.join(names[k] for k in wanted)}"
            )
        raise GenBacklashError(f"{file} has a header but no data rows")
    u, y = table[:, 0].copy(), table[:, 1].copy()
    t = table[:, 2].copy() if table.shape[1] == 3 else None
    after_gap = None
    if dropped and kept is not None:
        # a row after dropped ones does not follow the row before it
        after_gap = np.diff(np.asarray(kept), prepend=1) > 1
        after_gap[0] = after_gap[0] or kept[0] > 2
    clock = None if t is None else stamps_ns(t if exact_t is None else exact_t)
    if t is not None and clock is not None:
        # each row a reading and the command it holds: the commands in order are the rows'
        # changes of u, and the bag's rules choose the rows (select_rows)
        change = np.ones(u.size, dtype=bool)
        change[1:] = u[1:] != u[:-1]
        if motor:  # every row's motor reading is its own input, at its own stamp
            change[:] = True
        rows = select_rows(
            clock,
            np.cumsum(change) - 1,
            u[change],
            y,
            marks=after_gap,
            bridge=bridge,
            settle_ns=0 if motor else settle_ns,
            servo=None if motor else servo,
            input_stamps=clock[change] if motor else None,
        )
        if _in_ns(t):  # seconds from the first row kept, as a bag's series (from exact ns)
            t = (rows.t - rows.t[0]) / 1e9 if rows.t.size else rows.t.astype(np.float64)
        else:
            t = t[rows.index]
        return Series(
            u=rows.u,
            y=rows.y,
            t=t,
            breaks=rows.breaks,
            dropped=dropped,
            servo=rows.servo,
            servo_fit=rows.servo_fit,
        )
    if servo is not None:
        raise GenBacklashError(
            f"{file}: a servo model needs the readings' times: the CSV needs a 't' column of "
            "increasing stamps"
        )
    breaks = None if t is None else time_breaks(t)  # no clock: the stamps' steps alone
    if after_gap is not None:
        breaks = after_gap if breaks is None else breaks | after_gap
    return Series(u=u, y=y, t=t, breaks=breaks, dropped=dropped)


def _integer_column(file: Path, column: int, rows: int) -> npt.NDArray[np.int64] | None:
    """Column ``column`` of ``file`` as int64 when every cell is an integer literal (stamps in
    ns since the epoch do not fit a float64 exactly), else None."""
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)
            ints = np.loadtxt(
                file, delimiter=",", skiprows=1, usecols=[column], ndmin=1, dtype=np.int64
            )
    except (ValueError, OverflowError):
        return None
    return ints if ints.size == rows else None


def write_readings_csv(
    path: str | Path,
    t_ns: npt.ArrayLike,
    u: npt.ArrayLike,
    y: npt.ArrayLike,
    *,
    motor: bool = False,
) -> None:
    """Write readings as ``t,u,y``: ``t`` in integer nanoseconds (exact), ``u`` the command
    held at the reading and ``y`` the reading, at full float precision; what
    :func:`read_series_csv` reads back into the same rows. With ``motor`` the input column
    is ``motor`` (a motor encoder's reading at the reading's stamp: ``t,motor,y``)."""
    t = np.asarray(t_ns, dtype=np.int64)
    uu = np.asarray(u, dtype=np.float64)
    yy = np.asarray(y, dtype=np.float64)
    file = Path(path)
    file.parent.mkdir(parents=True, exist_ok=True)
    with file.open("w", newline="") as handle:
        handle.write("t,motor,y\n" if motor else "t,u,y\n")
        handle.writelines(
            f"{a},{b!r},{c!r}\n"
            for a, b, c in zip(t.tolist(), uu.tolist(), yy.tolist(), strict=True)
        )


def write_series_csv(path: str | Path, series: Series) -> None:
    """Write ``t,u,y`` (or ``u,y``) with full float precision."""
    columns = [series.u, series.y] if series.t is None else [series.t, series.u, series.y]
    header = "u,y" if series.t is None else "t,u,y"
    file = Path(path)
    file.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(
        file, np.column_stack(columns), delimiter=",", header=header, comments="", fmt="%.17g"
    )
