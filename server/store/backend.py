"""The store's interface: what the server asks of its database, whichever it is.

:class:`StoreBackend` is exactly the surface the server and the CLI use (the routers,
the ingest pipeline, the stream, the benches). Two classes have it:
:class:`~.database.SqliteStore` (``Store``, the embedded default: one file) and
:class:`~.postgres.database.PostgresStore` (a PostgreSQL + PostGIS server, for several
processes on one database). :func:`.opening.open_store` picks one from the settings.
Both answer every read with the same text on the same input (the read SQL is shared:
:mod:`.reading`); both acknowledge a detection batch only once its transaction has
committed.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, Protocol

from demtrack.core.tracking.types import Detection

from .batches import BatchMaker, StoredBatch
from .derived import FixRow
from .dialect import Dialect

__all__ = ["StoreBackend"]


class StoreBackend(Protocol):
    """A console store (the methods are documented on :class:`~.database.SqliteStore`)."""

    #: The store's random identity (the stream's ``hello``).
    store_id: str
    #: The SQL where the databases differ (:mod:`.markers` writes through it).
    dialect: Dialect

    @property
    def kind(self) -> str:
        """``"sqlite"`` or ``"postgres"``."""
        ...

    def close(self) -> None:
        """Close the store's connections."""
        ...

    # writing
    def _tx(self, fn: Callable[[Any], Any], *, sync: bool = True) -> Any:
        """Run ``fn(connection)`` in one write transaction (the store package's writers)."""
        ...

    def insert_batch(
        self, detections: Sequence[Detection], report: dict[str, Any], batch_key: str | None
    ) -> StoredBatch:
        """One durable batch (committed when it returns)."""
        ...

    def insert_batches(self, batches: Sequence[tuple[BatchMaker, str | None]]) -> list[StoredBatch]:
        """Several durable batches in one transaction (group commit)."""
        ...

    def write_derived(
        self,
        fixes: Iterable[FixRow],
        tracks: Iterable[dict[str, Any]],
        events: Iterable[tuple[str, Any]],
        *,
        replace_tracks: bool = False,
        keep_track_ids: Iterable[int] = (),
        activity: Iterable[dict[str, Any]] = (),
        fence: Any = None,
    ) -> list[tuple[int, str]]:
        """Fixes, tracks, activity and events in one transaction; each event's seq, text."""
        ...

    # reading
    def _snapshot(self) -> contextlib.AbstractContextManager[Any]:
        """The read connection inside one read transaction."""
        ...

    def _rows(self, sql: str, params: Sequence[Any] = ()) -> list[tuple[Any, ...]]:
        """The rows of one read statement (``?`` placeholders)."""
        ...

    def schema_version(self) -> int:
        """The applied schema version."""
        ...

    def counts(self) -> dict[str, int]:
        """Rows per counted table."""
        ...

    def last_seq(self) -> int:
        """The newest event's sequence number (0 when none)."""
        ...

    def last_times(self) -> dict[str, float]:
        """Latest accepted detection time per sensor (s)."""
        ...

    def sensor_counts(self) -> dict[str, int]:
        """Accepted detections per sensor."""
        ...

    def pose_last_times(self) -> dict[str, float]:
        """Each sensor's newest stored pose time (s)."""
        ...

    def poses(
        self,
        sensor: str,
        t_from: float | None = None,
        t_to: float | None = None,
        limit: int = 1_000_000,
    ) -> list[dict[str, Any]]:
        """Stored pose bodies of ``sensor`` in a time window."""
        ...

    def recent_poses(self, window_s: float) -> dict[str, list[dict[str, Any]]]:
        """Each sensor's recent pose bodies."""
        ...

    def detections(
        self, after_id: int = 0, limit: int = 1000, *, unprocessed: bool = False
    ) -> list[tuple[int, Detection]]:
        """Stored detections with ``id > after_id``, in id order."""
        ...

    def detections_in_window(
        self,
        sensors: Sequence[str],
        t_from: float,
        t_to: float,
        after_id: int = 0,
        limit: int = 1000,
    ) -> list[tuple[int, Detection]]:
        """Detections of ``sensors`` in a time window, by time then id."""
        ...

    def fixes(self, after_id: int = 0, limit: int = 1000) -> list[dict[str, Any]]:
        """Stored fix bodies, in detection order."""
        ...

    def events_since(self, seq: int, limit: int = 1000) -> list[dict[str, Any]]:
        """Stream messages with ``seq > seq``, oldest first."""
        ...

    def tracks(
        self,
        *,
        t_from: float | None = None,
        t_to: float | None = None,
        cls: str | None = None,
        bbox: tuple[float, float, float, float] | None = None,
    ) -> list[dict[str, Any]]:
        """Track bodies of a selection, by id."""
        ...

    def track_rows(
        self,
        known: Mapping[int, int],
        *,
        t_from: float | None = None,
        t_to: float | None = None,
        cls: str | None = None,
        bbox: tuple[float, float, float, float] | None = None,
        tails: bool = False,
    ) -> list[tuple[int, int, Any]]:
        """``(id, rev, body text or tail or None)`` of a selection, by id."""
        ...

    def track(self, track_id: int) -> dict[str, Any] | None:
        """One track's body (None if there is none)."""
        ...

    def activity(
        self,
        *,
        t_from: float | None = None,
        t_to: float | None = None,
        kinds: Sequence[str] | None = None,
        open_only: bool = False,
        limit: int = 10_000,
    ) -> list[dict[str, Any]]:
        """Activity bodies of a selection, by start time."""
        ...

    def latest_activity(self, kind: str) -> list[dict[str, Any]]:
        """The newest event body of ``kind`` per first track id."""
        ...
