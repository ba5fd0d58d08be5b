"""Opening the store the settings name: a SQLite file, or a PostgreSQL database.

:func:`open_store` takes the server's settings (``database_url`` set: PostgreSQL; else
the SQLite file ``resolved_db_path``), a ``postgresql://`` URL or a file path. A
PostgreSQL database that cannot be used (a malformed URL, a server that does not answer,
no PostGIS, a newer schema) is one line: :class:`~demtrack.core.errors.SettingsError`,
naming the URL without its password.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from demtrack.core.errors import SettingsError

from .backend import StoreBackend
from .database import SqliteStore

__all__ = ["open_store", "store_target"]


def store_target(settings_or_url: Any) -> str | Path:
    """The URL or the file :func:`open_store` opens for ``settings_or_url``."""
    from .postgres.connection import is_postgres_url

    if isinstance(settings_or_url, str | Path):
        return settings_or_url if is_postgres_url(settings_or_url) else Path(settings_or_url)
    url = getattr(settings_or_url, "database_url", None)
    return url if url else Path(settings_or_url.resolved_db_path)


def _postgres_error(url: str, exc: BaseException) -> SettingsError:
    """One line for a database that cannot be used; never the URL's password."""
    from urllib.parse import urlsplit

    from .postgres.connection import safe_url

    shown = safe_url(url)
    text = " ".join(str(exc).split()) or type(exc).__name__
    text = text.replace(url, shown)  # libpq may echo a malformed URL whole
    try:
        password = urlsplit(url).password
    except ValueError:
        password = None
    if password:
        text = text.replace(password, "***")
    if "postgis" in text.lower() and "control file" in text:  # not installed at all
        text = "the PostGIS extension is not installed on the server (postgresql-15-postgis-3)"
    return SettingsError(f"database {shown} cannot be used: {text}")


def open_store(settings_or_url: Any) -> StoreBackend:
    """The store of ``settings_or_url`` (settings, a database URL or a file path), open.

    Raises
    ------
    SettingsError
        A PostgreSQL database that cannot be used (see the module docstring). SQLite's
        errors are raised as they are (:func:`demtrack.server.app.check_startup` words
        them).
    """
    target = store_target(settings_or_url)
    if isinstance(target, Path):
        return SqliteStore(target)
    import psycopg

    from .postgres.database import PostgresStore

    try:
        return PostgresStore(target)
    except psycopg.Error as exc:
        raise _postgres_error(target, exc) from None
    except RuntimeError as exc:  # a newer schema
        raise _postgres_error(target, exc) from None
