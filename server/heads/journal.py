"""The heads' journal: every slew and assignment, one JSON line each, so a restart restores them.

A JSON-lines file beside the database (``<db>.heads.jsonl``), appended and flushed to disk
(``fsync``) for each row. Rows are rare -- an operator's command, a hand-off -- while
the per-tick follow commands are derived from the tracks and not journaled. A separate
file rather than a table: the store's schema and migrations belong to the store, and a
journal of a few rows per minute needs neither. A torn last line (power lost mid-write)
is skipped when read.

Row: ``{"t_s": UNIX s, "sensor_id": str, "mode": "idle"|"slew"|"look"|"follow"|"handoff",
...the mode's target}``. The last row of each sensor is its state at restart.
"""

from __future__ import annotations

import json
import logging
import os
import threading
from pathlib import Path
from typing import Any

__all__ = ["HeadJournal"]

log = logging.getLogger("demtrack.server")


class HeadJournal:
    """Append-only JSON lines at ``path`` (created when first written)."""

    def __init__(self, path: Path | None) -> None:
        self.path = None if path is None else Path(path)
        self._lock = threading.Lock()

    def append(self, row: dict[str, Any]) -> None:
        """Write one row durably (no-op without a path)."""
        if self.path is None:
            return
        line = json.dumps(row, separators=(",", ":"), allow_nan=False) + "\n"
        with self._lock, open(self.path, "a", encoding="utf-8") as fh:
            fh.write(line)
            fh.flush()
            os.fsync(fh.fileno())

    def rows(self) -> list[dict[str, Any]]:
        """Every readable row, in order (a torn or foreign line is skipped, once logged)."""
        if self.path is None or not self.path.is_file():
            return []
        out: list[dict[str, Any]] = []
        for k, line in enumerate(self.path.read_text("utf-8").splitlines(), 1):
            try:
                row = json.loads(line)
            except ValueError:
                log.warning("%s line %d is not JSON; skipped", self.path, k)
                continue
            if isinstance(row, dict) and isinstance(row.get("sensor_id"), str):
                out.append(row)
        return out

    def last_by_sensor(self) -> dict[str, dict[str, Any]]:
        """Each sensor's newest row."""
        return {row["sensor_id"]: row for row in self.rows()}
