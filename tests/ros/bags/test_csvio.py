"""CSV round trips and CSV error messages."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from genbacklash_core import GenBacklashError
from genbacklash_ros.bags.csvio import Series, read_series_csv, write_series_csv


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


def test_bad_cells_become_nan_for_the_identifier_to_report(tmp_path: Path) -> None:
    (tmp_path / "d.csv").write_text("u,y\n1,2\n,3\nabc,4\n5,nan\n")
    back = read_series_csv(tmp_path / "d.csv")
    assert back.u.size == 4
    assert np.isnan(back.u[1]) and np.isnan(back.u[2]) and np.isnan(back.y[3])


def test_missing_file_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(GenBacklashError, match="cannot read"):
        read_series_csv(tmp_path / "nope.csv")
