"""CSV round trips and CSV error messages."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.bags.csvio import Series, dropped_note, read_series_csv, write_series_csv


def test_round_trip_is_exact(tmp_path: Path) -> None:
    rng = np.random.default_rng(7)
    series = Series(u=rng.normal(size=50), y=rng.normal(size=50))
    write_series_csv(tmp_path / "d.csv", series)
    back = read_series_csv(tmp_path / "d.csv")
    assert np.array_equal(back.u, series.u)
    assert np.array_equal(back.y, series.y)
    assert back.t is None


def test_round_trip_with_time_column(tmp_path: Path) -> None:
    rng = np.random.default_rng(8)
    series = Series(u=rng.normal(size=20), y=rng.normal(size=20), t=np.arange(20) * 1e-3)
    write_series_csv(tmp_path / "d.csv", series)
    back = read_series_csv(tmp_path / "d.csv")
    assert back.t is not None
    assert np.array_equal(back.t, series.t)


def test_columns_found_by_name_in_any_order(tmp_path: Path) -> None:
    (tmp_path / "d.csv").write_text("y, extra ,U\n1.0,9,2.0\n3.0,9,4.0\n")
    back = read_series_csv(tmp_path / "d.csv")
    assert back.u.tolist() == [2.0, 4.0]
    assert back.y.tolist() == [1.0, 3.0]


def test_missing_column_is_named(tmp_path: Path) -> None:
    (tmp_path / "d.csv").write_text("u,position\n1,2\n")
    with pytest.raises(GenBacklashError, match=r"must name 'u' and 'y' \(missing: \['y'\]\)"):
        read_series_csv(tmp_path / "d.csv")


def test_empty_and_header_only_files(tmp_path: Path) -> None:
    (tmp_path / "e.csv").write_text("")
    with pytest.raises(GenBacklashError, match="is empty"):
        read_series_csv(tmp_path / "e.csv")
    (tmp_path / "h.csv").write_text("u,y\n")
    with pytest.raises(GenBacklashError, match="no data rows"):
        read_series_csv(tmp_path / "h.csv")


def test_bad_cells_become_nan_on_request(tmp_path: Path) -> None:
    (tmp_path / "d.csv").write_text("u,y\n1,2\n,3\nabc,4\n5,nan\n")
    back = read_series_csv(tmp_path / "d.csv", bad_rows="nan")
    assert back.u.size == 4
    assert np.isnan(back.u[1]) and np.isnan(back.u[2]) and np.isnan(back.y[3])


@pytest.mark.parametrize(
    ("body", "match"),
    [
        ("u,y\n1,2\n3,4\nabc,5\n", r"line 4 of .*d.csv, column 'u': 'abc' is not a number"),
        ("u,y\n1,2\n3,\n", r"line 3 of .*d.csv, column 'y': is empty"),
        ("u,y\n1,2\n3,inf\n", r"line 3 of .*d.csv, column 'y': 'inf' is not finite"),
        ("t,u,y\n0,1,2\nnan,3,4\n", r"line 3 of .*d.csv, column 't': 'nan' is not finite"),
        ("u,y\n1,2\n3\n4,5\n", r"line 3 of .*d.csv has 1 cell, too few for the columns u, y"),
        ("u,y\n# a comment\n\n1,2\n7;8\n", r"line 5 of .*d.csv has 1 cell"),
    ],
)
def test_a_bad_row_is_named_by_its_line(tmp_path: Path, body: str, match: str) -> None:
    (tmp_path / "d.csv").write_text(body)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # numpy's ConversionWarning no more
        with pytest.raises(GenBacklashError, match=match):
            read_series_csv(tmp_path / "d.csv")


def test_bad_rows_dropped_are_named_and_break_the_chain(tmp_path: Path) -> None:
    rows = [f"{k},{2 * k}" for k in range(10)]
    rows[3] = "x,6"  # line 5
    rows[4] = "4"  # line 6: short
    rows[8] = "8,nan"  # line 10
    (tmp_path / "d.csv").write_text("u,y\n" + "\n".join(rows) + "\n")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = read_series_csv(tmp_path / "d.csv", bad_rows="drop")
    assert back.u.tolist() == [0, 1, 2, 5, 6, 7, 9]
    assert back.dropped == (5, 6, 10)
    assert back.breaks is not None
    assert back.breaks.tolist() == [False, False, False, True, False, False, True]
    assert dropped_note("d.csv", back.dropped) == (
        "dropped 3 rows of d.csv that do not hold a finite number in every column used: "
        "lines 5, 6 and 10"
    )
    (tmp_path / "all.csv").write_text("u,y\na,b\n")
    with pytest.raises(GenBacklashError, match=r"every data row was dropped \(lines 2\)"):
        read_series_csv(tmp_path / "all.csv", bad_rows="drop")


def test_a_clean_file_takes_the_fast_path_and_drops_nothing(tmp_path: Path) -> None:
    (tmp_path / "d.csv").write_text("u,y\n1,2\n3,4\n")
    back = read_series_csv(tmp_path / "d.csv", bad_rows="drop")
    assert back.dropped == () and back.breaks is None


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(GenBacklashError, match="cannot read"):
        read_series_csv(tmp_path / "nope.csv")
