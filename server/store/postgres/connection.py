"""psycopg 3 connections for the store: ``?`` placeholders, and URLs fit to print.

The store's shared SQL (:mod:`demtrack.server.store.reading`, ``batches``, ``derived``,
``poses``, ``queries``) is written with SQLite's ``?`` placeholders; :class:`QmarkConnection`
runs it on a psycopg connection by turning each ``?`` into ``%s`` (none of those
statements holds a ``?`` or a ``%`` of its own). :func:`connect` opens a connection with
the store's settings, :func:`safe_url` is a URL with its password hidden (never print a
password) and :func:`is_postgres_url` tells a database URL from a file path.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Iterable, Sequence
from typing import Any
from urllib.parse import urlsplit, urlunsplit

import psycopg

__all__ = ["QmarkConnection", "connect", "is_postgres_url", "safe_url"]

_SCHEMES = ("postgresql", "postgres")


def is_postgres_url(value: object) -> bool:
    """Whether ``value`` is a ``postgresql://`` (or ``postgres://``) URL."""
    return isinstance(value, str) and value.split("://", 1)[0].lower() in _SCHEMES


def safe_url(url: str) -> str:
    """``url`` with its password (if any) replaced by ``***``: fit for a log or an error."""
    try:
        parts = urlsplit(url)
        if parts.password is None:
            return url
        host = parts.hostname or ""
        if parts.port is not None:
            host = f"{host}:{parts.port}"
        netloc = f"{parts.username or ''}:***@{host}"
        return urlunsplit((parts.scheme, netloc, parts.path, parts.query, parts.fragment))
    except ValueError:  # a malformed URL: say nothing of what it holds after the scheme
        return url.split("://", 1)[0] + "://***"


def connect(url: str, *, application_name: str = "demtrack") -> psycopg.Connection[Any]:
    """An autocommit connection (explicit transactions) with ``synchronous_commit=on``."""
    conn = psycopg.connect(
        url, autocommit=True, connect_timeout=10, application_name=application_name
    )
    conn.execute("SET synchronous_commit = on")
    return conn


@functools.lru_cache(maxsize=512)
def _pg(sql: str) -> str:
    return sql.replace("?", "%s")


class QmarkConnection:
    """A psycopg connection that takes ``?`` placeholders (the store's shared SQL).

    ``execute`` returns the psycopg cursor (``fetchone``, ``fetchall``, iteration; not
    ``rowcount``, which the store's pipelined writes do not have yet: the shared SQL reads
    ``RETURNING`` rows instead); ``raw`` is the connection itself.
    """

    def __init__(self, raw: psycopg.Connection[Any]) -> None:
        self.raw = raw
        self._column_types: dict[str, dict[str, str]] = {}

    def execute(self, sql: str, params: Sequence[Any] = ()) -> psycopg.Cursor[Any]:
        """Run one statement."""
        return self.raw.execute(_pg(sql), params if params else None)  # type: ignore[arg-type]

    def executemany(self, sql: str, rows: Iterable[Sequence[Any]]) -> psycopg.Cursor[Any]:
        """Run one statement for every row of parameters.

        An ``INSERT INTO t (cols) VALUES (?,...)``, optionally ``ON CONFLICT (col) DO ...``,
        runs as one statement over all rows: each column goes as one binary array
        parameter of the column's own type, ``unnest`` makes the rows (one round trip, one
        firing of the statement-level triggers, no text escaping, floats exact). An upsert
        keeps the last row of each key (what row-by-row upserts leave). Anything else runs
        once per row, pipelined by psycopg.
        """
        cur = self.raw.cursor()
        rows = list(rows)
        if not rows:
            return cur
        plan = _bulk_plan(sql)
        if plan is None:
            cur.executemany(_pg(sql), rows)  # type: ignore[arg-type]
            return cur
        table, cols, tail, key = plan
        if key is not None:  # one row per key, the last (ON CONFLICT may not hit a row twice)
            rows = list({r[key]: r for r in rows}.values())
        types = self._types(table, cols)
        arrays = [_coerce([r[j] for r in rows], t) for j, t in enumerate(types)]
        casts = ", ".join(f"%b::{t}[]" for t in types)
        names = ", ".join(cols)
        cur.execute(  # type: ignore[call-overload]
            f"INSERT INTO {table} ({names}) SELECT * FROM unnest({casts}){tail}",  # noqa: S608
            arrays,
        )
        return cur

    def _types(self, table: str, cols: tuple[str, ...]) -> list[str]:
        """The SQL types of ``table``'s columns ``cols`` (read once per table)."""
        known = self._column_types.get(table)
        if known is None:
            known = dict(
                self.raw.execute(
                    "SELECT attname, format_type(atttypid, NULL) FROM pg_attribute"
                    " WHERE attrelid = %s::regclass AND attnum > 0 AND NOT attisdropped",
                    (table,),
                ).fetchall()
            )
            self._column_types[table] = known
        return [known[c] for c in cols]


def _coerce(values: list[Any], sql_type: str) -> list[Any]:
    """``values`` as the Python type of ``sql_type`` (a list of one type for psycopg)."""
    if sql_type == "double precision":
        return [None if v is None else float(v) for v in values]
    if sql_type in ("bigint", "integer"):
        return [None if v is None else int(v) for v in values]
    return values


_INSERT = re.compile(
    r"\s*INSERT INTO (\w+) \(([\w\s,]+)\) VALUES \(([?,\s]+)\)"
    r"(\s+ON CONFLICT \((\w+)\) DO .*)?",
    re.DOTALL | re.IGNORECASE,
)


@functools.lru_cache(maxsize=256)
def _bulk_plan(sql: str) -> tuple[str, tuple[str, ...], str, int | None] | None:
    """``(table, columns, ON CONFLICT tail, key index)`` of a bulk insert, or None."""
    m = _INSERT.fullmatch(sql)
    if m is None or "RETURNING" in sql.upper():
        return None
    table, col_text, marks, tail, key = m.groups()
    cols = tuple(c.strip() for c in col_text.split(","))
    if marks.count("?") != len(cols):
        return None
    return table, cols, tail or "", (cols.index(key) if key else None)
