"""Markers kept by operators: rows of the ``markers`` table and their stream messages.

A marker and the ``marker`` stream message that announces it are written in one
transaction (the store's write lock), so a console that resumes from a
sequence number sees every marker added or removed since, and a reload lists exactly the
stored rows. The table is created by migration 6 (:func:`.schema.m6_markers`).
"""

from __future__ import annotations

from typing import Any

from .backend import StoreBackend
from .codec import dumps_json, loads_json

__all__ = ["add_marker", "delete_marker", "list_markers", "update_marker"]


def _append_event(store: StoreBackend, c: Any, payload: dict[str, Any]) -> tuple[int, str]:
    """Append ``payload`` to the event log with the next sequence number."""
    # The same numbering as derived rows (the dialect's): a sequence number is never reused.
    text = dumps_json(payload)
    (seq,) = store.dialect.append_events(c, [(payload["type"], text)])
    return seq, text


def add_marker(store: StoreBackend, body: dict[str, Any]) -> tuple[dict[str, Any], int, str]:
    """Store ``body`` (without ``id``) as a new marker; announce it on the stream.

    An empty ``name`` becomes ``M<id>``.

    Returns the stored body (``id`` filled in), the stream message's ``seq`` and its
    stored text (without ``seq``).
    """

    def tx(c: Any) -> tuple[dict[str, Any], int, str]:
        new_id = store.dialect.insert_id(
            c, "INSERT INTO markers (t_s, body) VALUES (?, ?)", (body["t_s"], dumps_json(body))
        )
        stored = {"id": new_id, **body}
        stored["name"] = stored.get("name") or f"M{stored['id']}"
        c.execute("UPDATE markers SET body = ? WHERE id = ?", (dumps_json(stored), stored["id"]))
        seq, text = _append_event(
            store, c, {"type": "marker", "action": "add", "id": stored["id"], "marker": stored}
        )
        return stored, seq, text

    out: tuple[dict[str, Any], int, str] = store._tx(tx)  # noqa: SLF001 (the store's writer)
    return out


def update_marker(
    store: StoreBackend, marker_id: int, fields: dict[str, Any]
) -> tuple[dict[str, Any], int, str] | None:
    """Set ``fields`` (name, note) of marker ``marker_id``; announce it. None: no such marker.

    An empty ``name`` becomes ``M<id>`` again.
    """

    def tx(c: Any) -> tuple[dict[str, Any], int, str] | None:
        row = c.execute("SELECT body FROM markers WHERE id = ?", (marker_id,)).fetchone()
        if row is None:
            return None
        body = {**loads_json(row[0]), **fields}
        body["name"] = body.get("name") or f"M{marker_id}"
        c.execute("UPDATE markers SET body = ? WHERE id = ?", (dumps_json(body), marker_id))
        seq, text = _append_event(
            store, c, {"type": "marker", "action": "update", "id": marker_id, "marker": body}
        )
        return body, seq, text

    out: tuple[dict[str, Any], int, str] | None = store._tx(tx)  # noqa: SLF001
    return out


def delete_marker(store: StoreBackend, marker_id: int) -> tuple[int, str] | None:
    """Remove marker ``marker_id``; announce it. None when there is no such marker."""

    def tx(c: Any) -> tuple[int, str] | None:
        if not c.execute("DELETE FROM markers WHERE id = ? RETURNING id", (marker_id,)).fetchall():
            return None
        return _append_event(
            store, c, {"type": "marker", "action": "delete", "id": marker_id, "marker": None}
        )

    out: tuple[int, str] | None = store._tx(tx)  # noqa: SLF001
    return out


def list_markers(store: StoreBackend) -> list[dict[str, Any]]:
    """Every stored marker's body, oldest first."""
    rows = store._rows("SELECT body FROM markers ORDER BY id")  # noqa: SLF001
    return [loads_json(r[0]) for r in rows]
