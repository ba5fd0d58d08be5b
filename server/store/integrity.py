"""The store's identity and health: its random id, its file, a full disk.

* **Identity.** Each database file gets a random ``store_id`` when it is created (table
  ``store_identity``, made at open when missing: an older file gets one on its first
  open). The stream sends it in ``hello``; a client whose ``since`` belongs to another
  store (a fresh database after a restart) starts over instead of waiting for the new
  file's sequence numbers to pass its old one.
* **The file.** The ``(device, inode)`` of the file is taken at open and checked before
  every write: a file deleted or replaced while the server runs would take every later
  acknowledged batch with it (SQLite keeps writing to the unlinked inode), so the store
  refuses to write from then on (:class:`StoreLostError`) and says so in the log, once.
* **A full disk** (or a size limit, ``PRAGMA max_page_count``) is :class:`StoreFullError`:
  the write is refused with one line, reads go on, and the next write after space
  returns succeeds.

These errors, and :class:`StoreUnreachableError` (a PostgreSQL server that went away), are
:class:`StoreUnavailableError`; the API answers 507 (full) or 503 (lost, unreachable) with
the message.
"""

from __future__ import annotations

import errno
import logging
import os
import secrets
import sqlite3
from pathlib import Path

__all__ = [
    "FileIdentity",
    "StoreFullError",
    "StoreLostError",
    "StoreUnavailableError",
    "StoreUnreachableError",
    "ensure_store_id",
    "translate_write_error",
]

log = logging.getLogger("demtrack.server")


class StoreUnavailableError(RuntimeError):
    """A write the store cannot make now (nothing of it was committed).

    ``retryable``: whether the same write may pass later (space returns, the server comes
    back); False where it never can (a write fenced out of a lost cluster lease).
    """

    retryable = True


class StoreFullError(StoreUnavailableError):
    """The disk (or the file's size limit) is full: the write was rolled back."""


class StoreLostError(StoreUnavailableError):
    """The database file was deleted or replaced while the server ran."""


class StoreUnreachableError(StoreUnavailableError):
    """The database server (PostgreSQL) could not be reached: nothing was written."""


def ensure_store_id(conn: sqlite3.Connection) -> str:
    """The file's random store id, made (and committed) on first call.

    Not a numbered migration: it is the file's identity, not a schema step, and needs no
    place in the migration order.
    """
    conn.execute("CREATE TABLE IF NOT EXISTS store_identity (store_id TEXT NOT NULL)")
    row = conn.execute("SELECT store_id FROM store_identity").fetchone()
    if row is not None:
        return str(row[0])
    store_id = secrets.token_hex(8)
    conn.execute("BEGIN IMMEDIATE")
    try:
        row = conn.execute("SELECT store_id FROM store_identity").fetchone()
        if row is None:
            conn.execute("INSERT INTO store_identity (store_id) VALUES (?)", (store_id,))
        else:
            store_id = str(row[0])
        conn.execute("COMMIT")
    except BaseException:
        conn.execute("ROLLBACK")
        raise
    return store_id


class FileIdentity:
    """The database file as opened: checked before each write (see the module docstring)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        st = os.stat(path)
        self._id = (st.st_dev, st.st_ino)
        self.lost: str | None = None

    def check(self) -> None:
        """Raise :class:`StoreLostError` if the file is gone or another file has its name."""
        if self.lost is None:
            try:
                st = os.stat(self.path)
            except FileNotFoundError:
                self.lost = "deleted"
            except OSError as exc:
                self.lost = f"unreadable ({exc.strerror})"
            else:
                if (st.st_dev, st.st_ino) != self._id:
                    self.lost = "replaced by another file"
            if self.lost is not None:
                log.critical(
                    "database %s was %s while the server ran: refusing every write from now"
                    " on (batches are no longer acknowledged); restart the server",
                    self.path,
                    self.lost,
                )
        if self.lost is not None:
            raise StoreLostError(
                f"the database file {self.path} was {self.lost} while the server ran;"
                " nothing is stored or acknowledged until the server is restarted"
            )


def _is_full(exc: BaseException) -> bool:
    code = getattr(exc, "sqlite_errorcode", None)
    if code == sqlite3.SQLITE_FULL:
        return True
    if isinstance(exc, OSError) and exc.errno == errno.ENOSPC:
        return True
    return isinstance(exc, sqlite3.OperationalError) and "disk is full" in str(exc)


def translate_write_error(exc: BaseException, path: Path) -> BaseException:
    """``exc`` as the store reports it: :class:`StoreFullError` for a full disk, else itself."""
    if _is_full(exc):
        return StoreFullError(
            f"the database {path} is full (no space left on the disk or its size limit):"
            " nothing was stored; retry once space is freed"
        )
    return exc
