"""Reading and writing input/output series as CSV with a header (``u,y`` and optional ``t``).

A ``t`` column gives the record its sample rule (:mod:`genbacklash_core.samples`): a row
that is not one nominal period (the median difference of ``t``, rounded) after the row
before it -- a lost sample, a gap -- breaks the chain of consecutive samples, so that
``identify`` and ``diagnose`` never form a regression row across it. ``t`` may be in seconds
or in integer nanoseconds (or any one unit): only differences in units of the median one
count. Without ``t`` every row follows the one before it.
"""

from __future__ import annotations

import csv
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from genbacklash_core import GenBacklashError
from genbacklash_ros.node.sample_rule import time_breaks

__all__ = ["Series", "read_series_csv", "write_series_csv"]

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True, eq=False)
class Series:
    """An input/output record: command ``u``, measured output ``y``, optional time ``t`` [s].

    ``breaks`` (optional, bool): the sample rule, True where a sample does not follow the
    one before it on the encoder's clock (None: all do); for the identifiers' ``breaks``.
    """

    u: FloatArray
    y: FloatArray
    t: FloatArray | None = None
    breaks: npt.NDArray[np.bool_] | None = None


def read_series_csv(path: str | Path) -> Series:
    """Read a CSV whose header names the columns ``u`` and ``y`` (and optionally ``t``).

    With ``t`` the series carries its ``breaks`` (see the module notes). Other columns are
    ignored. Empty or non-numeric cells become NaN, so the identifiers can
    report where they are (or drop them on request) instead of failing here.
    """
    file = Path(path)
    try:
        with file.open(newline="") as handle:
            header = next(csv.reader(handle), None)
    except OSError as err:
        raise GenBacklashError(f"cannot read {file}: {err.strerror or err}") from err
    except UnicodeDecodeError as err:
        raise GenBacklashError(f"{file} is not a text CSV file: {err}") from err
    if not header:
        raise GenBacklashError(f"{file} is empty; expected a header line with columns u,y")
    names = [name.strip().lower() for name in header]
    missing = [c for c in ("u", "y") if c not in names]
    if missing:
        raise GenBacklashError(
            f"{file} has columns {header}; the header must name 'u' and 'y' (missing: {missing})"
        )
    wanted = [names.index("u"), names.index("y")] + ([names.index("t")] if "t" in names else [])
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "no data": reported below instead
            table = np.loadtxt(file, delimiter=",", skiprows=1, usecols=wanted, ndmin=2)
    except ValueError:
        # Empty or malformed cells: parse tolerantly, marking them NaN for the caller to report.
        table = np.genfromtxt(
            file,
            delimiter=",",
            skip_header=1,
            usecols=wanted,
            dtype=np.float64,
            ndmin=2,
            invalid_raise=False,
        )
    if table.shape[0] == 0:
        raise GenBacklashError(f"{file} has a header but no data rows")
    t = table[:, 2].copy() if table.shape[1] == 3 else None
    breaks = None if t is None else time_breaks(t)
    return Series(u=table[:, 0].copy(), y=table[:, 1].copy(), t=t, breaks=breaks)


def write_series_csv(path: str | Path, series: Series) -> None:
    """Write ``t,u,y`` (or ``u,y``) with full float precision."""
    columns = [series.u, series.y] if series.t is None else [series.t, series.u, series.y]
    header = "u,y" if series.t is None else "t,u,y"
    file = Path(path)
    file.parent.mkdir(parents=True, exist_ok=True)
    np.savetxt(
        file, np.column_stack(columns), delimiter=",", header=header, comments="", fmt="%.17g"
    )
