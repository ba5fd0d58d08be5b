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

    ``execute`` returns the psycopg cursor (``fetchone``, ``fetchall``, iteration,
    ``rowcount``); ``raw`` is the connection itself.
    """

    def __init__(self, raw: psycopg.Connection[Any]) -> None:
        self.raw = raw

    def execute(self, sql: str, params: Sequence[Any] = ()) -> psycopg.Cursor[Any]:
        """Run one statement."""
        return self.raw.execute(_pg(sql), params if params else None)  # type: ignore[arg-type]

    def executemany(self, sql: str, rows: Iterable[Sequence[Any]]) -> psycopg.Cursor[Any]:
        """Run one statement once per row of parameters (pipelined by psycopg)."""
        cur = self.raw.cursor()
        rows = list(rows)
        if rows:
            cur.executemany(_pg(sql), rows)  # type: ignore[arg-type]
        return cur
