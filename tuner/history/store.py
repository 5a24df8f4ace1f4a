"""The history database: opened by SQLAlchemy URL (a SQLite file by default, PostgreSQL for a fleet), created and
upgraded by this package's Alembic migrations (``migrations/``, run programmatically, version table
``lf_alembic_version``), written by :class:`History`.

* **Only a history database is touched.** A database that holds tables but not this program's version table (a
  user's SQLite file, another application's schema) is refused before anything is written, and so is one
  migrated by a newer version of this program; a file that is not a database at all is refused as well.
* **The log stays the source of truth.** A database that cannot be reached or written is reported in one line
  (:class:`HistoryError`); live goes on without it (:class:`tuner.history.writer.HistoryWriter`), and
  ``history --rebuild`` fills it in from the logs later.
"""

from __future__ import annotations

import contextlib
import logging
import os

import sqlalchemy as sa

from tuner.history import schema as s
from twin.errors import TwinError

log = logging.getLogger(__name__)

DEFAULT_DB = "twin_history.sqlite"  # in the working folder
MIGRATIONS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "migrations")
CONNECT_TIMEOUT_S = 5


class HistoryError(TwinError):
    """The history database cannot be opened, is not ours, or cannot be written."""


def default_url() -> str:
    return f"sqlite:///{os.path.abspath(DEFAULT_DB)}"


def display(url: str) -> str:
    """The URL without its password, for messages."""
    try:
        return sa.engine.make_url(url).render_as_string(hide_password=True)
    except Exception:
        return url


BACKENDS = ("sqlite", "postgresql")  # what the migrations are written and tested for


def _engine(url: str) -> sa.Engine:
    try:
        parsed = sa.engine.make_url(url)
    except Exception:
        raise HistoryError(f"--db {url}: not a database URL (e.g. sqlite:///history.sqlite, "
                           "postgresql+psycopg://user@host/db)") from None
    args = {}
    if parsed.get_backend_name() not in BACKENDS:
        raise HistoryError(f"--db {display(url)}: {parsed.get_backend_name()} is not a database the history runs on; "
                           "give sqlite:///FILE or postgresql+psycopg://user@host/db")
    if parsed.drivername == "postgresql":  # SQLAlchemy's default driver is psycopg2; this package brings psycopg 3
        parsed = parsed.set(drivername="postgresql+psycopg")
    if parsed.get_backend_name() == "sqlite":
        database = parsed.database
        if database and database != ":memory:" and not database.startswith("file:"):
            folder = os.path.dirname(os.path.abspath(database))
            if os.path.isdir(database):
                raise HistoryError(f"--db {url}: {database} is a folder")
            if not os.path.isdir(folder):
                raise HistoryError(f"--db {url}: folder {folder} does not exist")
        args["connect_args"] = {"timeout": CONNECT_TIMEOUT_S}
    elif parsed.get_backend_name() == "postgresql":
        args["connect_args"] = {"connect_timeout": CONNECT_TIMEOUT_S}
    try:
        return sa.create_engine(parsed, **args)
    except ImportError as e:  # a driver that is not installed
        raise HistoryError(f"--db {display(url)}: its driver {e.name or ''} is not installed (for PostgreSQL give "
                           "postgresql+psycopg://…, whose driver pip install -e '.[fleet]' brings)") from None
    except Exception as e:  # a dialect SQLAlchemy does not know
        raise HistoryError(f"--db {display(url)}: {_why(e)}") from None


def check_db(url: str) -> None:
    """What can be refused before any work: a URL that does not parse, a SQLite file in a folder that does not
    exist, a SQLite file that is not a history database of ours (it is left as it is). A server is not contacted
    here: one that cannot be reached is reported when it is used, and the run goes on."""
    engine = _engine(url)
    try:
        if engine.dialect.name == "sqlite" and engine.url.database and os.path.isfile(engine.url.database):
            try:
                with engine.connect() as c:
                    _refuse_foreign(c, url)
            except sa.exc.SQLAlchemyError as e:
                raise HistoryError(f"--db {display(url)}: not a database ({_why(e)}); it is left as it is") from None
    finally:
        engine.dispose()


def _foreign(connection) -> list[str]:
    """What a database without this program's version table holds of someone else's: its tables and views, and
    in SQLite a ``user_version`` or ``application_id`` set (empty: nothing, it may become a history)."""
    inspector = sa.inspect(connection)
    out = [f"table {t}" for t in sorted(inspector.get_table_names())]
    out += [f"view {v}" for v in sorted(inspector.get_view_names())]
    if connection.dialect.name == "sqlite":
        for pragma in ("user_version", "application_id"):
            value = connection.exec_driver_sql(f"PRAGMA {pragma}").scalar()
            if value:
                out.append(f"{pragma} {value}")
    return out


def _refuse_foreign(connection, url: str) -> str | None:
    """The database's revision of ours (None: none yet); one that holds anything else of someone's, or was
    migrated by a newer version of this program, is refused."""
    revision = current_revision(connection)
    if revision is None:
        foreign = _foreign(connection)
        if foreign:
            shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
            raise HistoryError(f"--db {display(url)}: holds {shown} but is not a history database of this program; "
                               "it is left as it is: give another --db")
    elif revision not in _known_revisions():
        raise HistoryError(f"--db {display(url)}: was migrated to revision {revision} by a newer version of this "
                           "program; upgrade this one to use it")
    return revision


def _why(e: BaseException) -> str:
    text = str(getattr(e, "orig", None) or e).strip().splitlines()
    return text[0] if text else type(e).__name__


def _alembic_config(connection):
    from alembic.config import Config

    cfg = Config()
    cfg.set_main_option("script_location", MIGRATIONS)
    cfg.attributes["connection"] = connection
    return cfg


def head() -> str:
    from alembic.script import ScriptDirectory

    return ScriptDirectory.from_config(_alembic_config(None)).get_current_head()


def current_revision(connection) -> str | None:
    inspector = sa.inspect(connection)
    if not inspector.has_table(s.VERSION_TABLE):
        return None
    return connection.execute(sa.text(f"SELECT version_num FROM {s.VERSION_TABLE}")).scalar()


UPGRADE_WAIT_S = 60  # [s] at most waited for another process that is creating or upgrading the same database
_PG_LOCK = 0x6C665F68  # the advisory lock the history's creators take in a PostgreSQL database ("lf_h")


def _serialise(connection) -> None:
    """Take the database's write lock before looking at it, so that of processes creating (or upgrading) the
    same database at once one does it and the others wait, then find it done: a SQLite write transaction
    (``BEGIN IMMEDIATE``), a PostgreSQL advisory lock held to the end of the transaction."""
    if connection.dialect.name == "sqlite":
        connection.exec_driver_sql(f"PRAGMA busy_timeout = {UPGRADE_WAIT_S * 1000}")
        connection.exec_driver_sql("BEGIN IMMEDIATE")  # (pysqlite would begin only before the first row written)
    elif connection.dialect.name == "postgresql":
        connection.exec_driver_sql(f"SET LOCAL lock_timeout = '{UPGRADE_WAIT_S}s'")
        connection.execute(sa.text("SELECT pg_advisory_xact_lock(:key)"), {"key": _PG_LOCK})


def upgrade(engine: sa.Engine, url: str) -> None:
    """Create or upgrade the schema to the newest migration, in one transaction under the database's write lock;
    refuse a database that is not a history of ours."""
    from alembic import command

    with engine.begin() as connection:
        _serialise(connection)
        try:
            if _refuse_foreign(connection, url) != head():
                command.upgrade(_alembic_config(connection), "head")
        finally:
            if connection.dialect.name == "sqlite":
                connection.exec_driver_sql(f"PRAGMA busy_timeout = {CONNECT_TIMEOUT_S * 1000}")


def _known_revisions() -> set[str]:
    from alembic.script import ScriptDirectory

    return {r.revision for r in ScriptDirectory.from_config(_alembic_config(None)).walk_revisions()}


class History:
    """An open, up-to-date history database.

    Args:
      url: SQLAlchemy URL.
    """

    def __init__(self, url: str):
        self.url = url
        self.engine = _engine(url)
        try:
            upgrade(self.engine, url)
        except HistoryError:
            self.engine.dispose()
            raise
        except Exception as e:
            self.engine.dispose()
            raise HistoryError(f"--db {display(url)}: cannot open the history database ({_why(e)})") from None

    def close(self) -> None:
        self.engine.dispose()

    @contextlib.contextmanager
    def begin(self):
        """A transaction; a database error becomes :class:`HistoryError`, naming the database and the cause."""
        try:
            with self.engine.begin() as c:
                yield c
        except sa.exc.SQLAlchemyError as e:
            raise HistoryError(f"--db {display(self.url)}: cannot write the history ({_why(e)})") from None

    # --- rows ----------------------------------------------------------------------------------------------------

    @staticmethod
    def robot(c, name: str, kind: str = "robot", when: float | None = None) -> int:
        """The robot's id, created on first sight; its first and last sighting follow ``when``."""
        row = c.execute(sa.select(s.robots).where(s.robots.c.name == name)).first()
        if row is None:
            return c.execute(s.robots.insert().values(name=name, kind=kind, first_seen=when, last_seen=when)
                             ).inserted_primary_key[0]
        if when is not None:
            first = when if row.first_seen is None else min(row.first_seen, when)
            last = when if row.last_seen is None else max(row.last_seen, when)
            c.execute(s.robots.update().where(s.robots.c.id == row.id).values(first_seen=first, last_seen=last))
        return row.id

    @staticmethod
    def put(c, table: sa.Table, source: str, **values) -> int:
        """Insert the row with this source key, or replace the one there."""
        row = c.execute(sa.select(table.c.id).where(table.c.source == source)).first()
        if row is None:
            return c.execute(table.insert().values(source=source, **values)).inserted_primary_key[0]
        c.execute(table.update().where(table.c.id == row.id).values(**values))
        return row.id

    def forget_log(self, c, key: str, log_path: str) -> int:
        """Delete every row that came from this telemetry log (before it is rebuilt): its rows keyed ``<key>#…``,
        from any copy of it, and those keyed by its path by versions before logs had ids; how many runs it had."""
        keyed = sa.or_(s.runs.c.source.startswith(f"{key}#", autoescape=True),
                       sa.and_(s.runs.c.log_path == log_path, s.runs.c.source.startswith(f"{log_path}#", autoescape=True)))
        ids = [r.id for r in c.execute(sa.select(s.runs.c.id).where(keyed))]
        for table in (s.laps, s.alignments, s.gain_changes, s.events):
            c.execute(table.delete().where(table.c.run_id.in_(ids)))
        c.execute(s.runs.delete().where(s.runs.c.id.in_(ids)))
        used = sa.select(s.runs.c.robot_id)
        c.execute(s.robots.delete().where(s.robots.c.id.not_in(used)))  # robots known only from that log
        return len(ids)
