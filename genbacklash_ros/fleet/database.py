"""The fleet results database: one table, one row per bag and joint (SQLAlchemy Core).

An SQLite file by default (``sqlite:///fleet.db``; a plain path is taken as one), any other
database SQLAlchemy supports by its URL (``postgresql+psycopg://user@host/fleet``, with that
database's driver installed). :class:`ResultStore` creates the table when it is missing.

Table ``bag_results`` (docs/fleet.md lists the columns with example queries):

* identity: ``id``; ``bag_hash`` (SHA-256 of the bag's content), ``joint``,
  ``settings_key`` (SHA-256 of the analysis settings) -- unique together, so a re-run with
  the same settings skips a bag it has, and a result is never stored twice;
* where and when: ``robot``, ``bag_path`` (relative to the archive), ``archive``,
  ``recorded_ns`` / ``recorded_at`` (the bag's time, ns since the epoch and ISO 8601 UTC),
  ``time_source`` (``name``, ``directory``, ``metadata``);
* outcome: ``status`` (``ok``, ``poor_fit``, ``not_converged``, ``no_motion``,
  ``unreadable``, ``failed``: :data:`~genbacklash_ros.fleet.job.STATUSES`), ``reason``;
* the batch estimate: ``model``, ``degree``, ``command_index``, ``c_left``, ``c_left_std``,
  ``c_right``, ``c_right_std``, ``gap`` (``c_L + c_R``), ``gap_std``, ``parameters`` and
  ``parameter_std`` (JSON name -> value), ``estimate`` (the identify JSON model),
  ``nrmse`` (free-run fit), ``iterations``, ``converged``, ``n_samples``, ``duration_s``;
* diagnose: ``diagnose_effects`` (comma-separated effect names, ``""`` for none),
  ``diagnose_gap_initial``, ``diagnose_gap_final``, ``diagnosis`` (the diagnose JSON);
* replay (``--replay``): ``replay_gap``, ``replay_gap_std``, ``replay_state``, ``replay``
  (the replay JSON summary);
* provenance: ``settings`` (JSON), ``software_version``, ``processed_at`` (ISO 8601 UTC),
  ``compute_s``;
* a cut recording: ``truncated`` (True when the bag is damaged part-way and its readable
  part was analysed; False when read to its end; NULL in rows written before the column
  existed) and ``recorded_s`` (the recording's length by its metadata, NULL when unknown).

**Columns added later.** A table written by an older genbacklash lacks the columns added
since (:data:`ADDED_COLUMNS`). ``genbacklash fleet`` adds them when it opens the table
(``ALTER TABLE ... ADD COLUMN``, nullable: the old rows read NULL, unknown) and nothing else
changes; ``fleet-report`` only reads, and reads an older table as it is (a missing column
reads as None).

Each bag's rows are written in one transaction, so a run killed at any moment leaves whole
bags or nothing; the next run redoes only what is missing.

Examples
--------
>>> import tempfile
>>> from genbacklash_ros.fleet.job import BagResult
>>> with tempfile.TemporaryDirectory() as tmp:
...     store = ResultStore(f"{tmp}/fleet.db")
...     row = BagResult("ab12", "elbow", "k1", "robot-1", "robot-1/a.mcap", "no_motion")
...     store.add([row], archive="/data"), store.add([row], archive="/data")
...     [(r.robot, r.joint, r.status) for r in store.results()]
...     store.close()
(1, 0)
[('robot-1', 'elbow', 'no_motion')]
"""

from __future__ import annotations

import datetime as dt
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from sqlalchemy import (
    JSON,
    BigInteger,
    Boolean,
    Column,
    Engine,
    Float,
    Integer,
    MetaData,
    Row,
    String,
    Table,
    Text,
    UniqueConstraint,
    create_engine,
    event,
    inspect,
    null,
    select,
    text,
)
from sqlalchemy.exc import ArgumentError, IntegrityError, OperationalError, SQLAlchemyError

from genbacklash_core import GenBacklashError
from genbacklash_ros.fleet.job import BagResult

__all__ = ["ADDED_COLUMNS", "TABLE", "ResultStore", "database_url", "iso_utc"]

metadata = MetaData()

TABLE = Table(
    "bag_results",
    metadata,
    Column("id", Integer, primary_key=True, autoincrement=True),
    Column("bag_hash", String(64), nullable=False),
    Column("joint", String(200), nullable=False),
    Column("settings_key", String(64), nullable=False),
    Column("robot", String(200), nullable=False, index=True),
    Column("bag_path", Text, nullable=False),
    Column("archive", Text),
    Column("recorded_ns", BigInteger),
    Column("recorded_at", String(32), index=True),
    Column("time_source", String(16)),
    Column("status", String(16), nullable=False, index=True),
    Column("reason", Text, nullable=False, default=""),
    Column("command_index", Integer),
    Column("model", String(16)),
    Column("degree", Integer),
    Column("c_left", Float),
    Column("c_left_std", Float),
    Column("c_right", Float),
    Column("c_right_std", Float),
    Column("gap", Float),
    Column("gap_std", Float),
    Column("parameters", JSON),
    Column("parameter_std", JSON),
    Column("estimate", JSON),
    Column("nrmse", Float),
    Column("iterations", Integer),
    Column("converged", Boolean),
    Column("n_samples", Integer),
    Column("duration_s", Float),
    Column("diagnose_effects", Text),
    Column("diagnose_gap_initial", Float),
    Column("diagnose_gap_final", Float),
    Column("diagnosis", JSON),
    Column("replay_gap", Float),
    Column("replay_gap_std", Float),
    Column("replay_state", String(32)),
    Column("replay", JSON),
    Column("settings", JSON),
    Column("software_version", String(32), nullable=False),
    Column("processed_at", String(32), nullable=False),
    Column("compute_s", Float),
    Column("truncated", Boolean),
    Column("recorded_s", Float),
    UniqueConstraint("bag_hash", "joint", "settings_key", name="one_result_per_bag_joint"),
)
"""The ``bag_results`` table."""

ADDED_COLUMNS = ("truncated", "recorded_s")
"""Columns added after the table's first release, in order: nullable, added to an older table
by :class:`ResultStore` (see the module notes)."""


def _columns_of(conn: Any) -> set[str]:
    """The column names of the stored ``bag_results`` table."""
    return {str(column["name"]) for column in inspect(conn).get_columns(TABLE.name)}


def iso_utc(ns: int | None) -> str | None:
    """ns since the epoch -> ``YYYY-MM-DDTHH:MM:SSZ`` (None stays None).

    >>> iso_utc(1709627400000000000)
    '2024-03-05T08:30:00Z'
    """
    if ns is None:
        return None
    stamp = dt.datetime.fromtimestamp(ns / 1e9, tz=dt.timezone.utc)
    return stamp.strftime("%Y-%m-%dT%H:%M:%SZ")


def database_url(db: str | Path) -> str:
    """``db`` as an SQLAlchemy URL: a URL (``dialect://...``) as given, a path as SQLite.

    >>> database_url("results/fleet.db")
    'sqlite:///results/fleet.db'
    >>> database_url("postgresql+psycopg://me@host/fleet")
    'postgresql+psycopg://me@host/fleet'
    """
    text = str(db)
    return text if "://" in text else f"sqlite:///{text}"


def _sqlite_pragmas(dbapi_connection: Any, _record: Any) -> None:
    # WAL: readers (fleet-report) do not block the writer; full sync: a committed bag survives
    # a kill -9 or a power cut
    cursor = dbapi_connection.cursor()
    cursor.execute("PRAGMA journal_mode=WAL")
    cursor.execute("PRAGMA synchronous=FULL")
    cursor.close()


class ResultStore:
    """The results table of one database (created when missing).

    Parameters
    ----------
    db : str or Path
        An SQLAlchemy URL, or a file path for SQLite (its directory must exist).
    create : bool
        Create the table when it is missing (False: a database without it is an error, as
        ``fleet-report`` wants).
    """

    def __init__(self, db: str | Path, *, create: bool = True) -> None:
        url = database_url(db)
        if url.startswith("sqlite:///") and not create:
            path = Path(url.removeprefix("sqlite:///"))
            if not path.is_file():
                raise GenBacklashError(f"no database at {path}; run 'genbacklash fleet' first")
        if url.startswith("sqlite:///"):
            parent = Path(url.removeprefix("sqlite:///")).parent
            if not parent.is_dir():
                raise GenBacklashError(f"cannot create the database: {parent} is not a directory")
        try:
            self.engine: Engine = create_engine(url)
        except (ArgumentError, ImportError, SQLAlchemyError) as err:
            raise GenBacklashError(f"cannot use the database {url!r}: {err}") from err
        if self.engine.dialect.name == "sqlite" and create:
            # the writer's settings; a reader (fleet-report) leaves the file as it is (the
            # journal mode is stored in the file)
            event.listen(self.engine, "connect", _sqlite_pragmas)
        try:
            if create:
                metadata.create_all(self.engine)
                self._present = self._add_missing_columns()
            else:
                with self.engine.connect() as conn:
                    if not self.engine.dialect.has_table(conn, TABLE.name):
                        raise GenBacklashError(
                            f"{url} has no {TABLE.name} table; is it a 'genbacklash fleet' "
                            "database?"
                        )
                    self._present = _columns_of(conn)
        except (OperationalError, SQLAlchemyError) as err:
            raise GenBacklashError(
                f"cannot open the database {url}: {getattr(err, 'orig', None) or err}"
            ) from err

    def _add_missing_columns(self) -> set[str]:
        """Add to an older table the columns of :data:`ADDED_COLUMNS` it lacks (nullable,
        no default: its rows read NULL); returns the table's columns after."""
        with self.engine.begin() as conn:
            present = _columns_of(conn)
            quote = conn.dialect.identifier_preparer.quote
            for name in ADDED_COLUMNS:
                if name in present:
                    continue
                column = TABLE.c[name]
                kind = column.type.compile(dialect=conn.dialect)
                conn.execute(
                    text(f"ALTER TABLE {quote(TABLE.name)} ADD COLUMN {quote(name)} {kind}")
                )
                present.add(name)
        return present

    def close(self) -> None:
        """Release the connections."""
        self.engine.dispose()

    def __enter__(self) -> ResultStore:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def done_keys(self) -> set[tuple[str, str, str]]:
        """Every stored ``(bag_hash, joint, settings_key)``."""
        columns = (TABLE.c.bag_hash, TABLE.c.joint, TABLE.c.settings_key)
        with self.engine.connect() as conn:
            return {(a, b, c) for a, b, c in conn.execute(select(*columns))}

    def add(self, results: Sequence[BagResult], *, archive: str = "") -> int:
        """Store one bag's rows in one transaction; rows already there (same hash, joint and
        settings key) are left as they are. Returns the number of rows added."""
        now = iso_utc(int(dt.datetime.now(dt.timezone.utc).timestamp() * 1e9))
        added = 0
        with self.engine.begin() as conn:
            for result in results:
                row = result.to_row()
                key = (
                    (TABLE.c.bag_hash == row["bag_hash"])
                    & (TABLE.c.joint == row["joint"])
                    & (TABLE.c.settings_key == row["settings_key"])
                )
                if conn.execute(select(TABLE.c.id).where(key)).first() is not None:
                    continue
                row.update(
                    archive=archive, recorded_at=iso_utc(row["recorded_ns"]), processed_at=now
                )
                try:
                    with conn.begin_nested():
                        conn.execute(TABLE.insert().values(**row))
                except IntegrityError:  # another writer stored it meanwhile
                    continue
                added += 1
        return added

    def results(self, statuses: Iterable[str] | None = None) -> list[Row[Any]]:
        """Every row (or those of ``statuses``), ordered by robot, joint and time; a column
        an older table lacks reads as None."""
        columns = [c if c.name in self._present else null().label(c.name) for c in TABLE.c]
        query = select(*columns).order_by(
            TABLE.c.robot, TABLE.c.joint, TABLE.c.recorded_ns, TABLE.c.id
        )
        if statuses is not None:
            query = query.where(TABLE.c.status.in_(list(statuses)))
        with self.engine.connect() as conn:
            return list(conn.execute(query))
