"""Helpers of the head tests: a sample-site copy with active heads, a scripted track source."""

from __future__ import annotations

import json
import shutil
import threading
from pathlib import Path
from typing import Any

import numpy as np

from demtrack.core.tracking.types import Track, TrackPoint

T0 = 1.8e9  # scenario time 0 as a real clock time


def active_site(
    sample_site_dir: Path, dest: Path, entries: dict[str, dict[str, Any] | None]
) -> Path:
    """A copy of the sample site; ``entries``: sensor id -> extra manifest keys (None drops it).

    Sensors not named stay as they are (fixed).
    """
    shutil.copytree(sample_site_dir, dest, ignore=shutil.ignore_patterns("*.npy", "*.sqlite3*"))
    doc = json.loads((dest / "site.json").read_text("utf-8"))
    sensors = []
    for s in doc["sensors"]:
        if s["id"] in entries and entries[s["id"]] is None:
            continue
        s.update(entries.get(s["id"]) or {})
        sensors.append(s)
    doc["sensors"] = sensors
    (dest / "site.json").write_text(json.dumps(doc, indent=2), "utf-8")
    return dest


class Clock:
    """A settable clock (UNIX seconds)."""

    def __init__(self, t: float = T0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


class _Commits:
    def __init__(self) -> None:
        self.lock = threading.Lock()


class ScriptedTracks:
    """Stands in for the pipeline: one track that follows a truth path as ``clock`` runs.

    ``tracker.tracks()`` returns the track with the truth points of the last 3 s up to
    the clock's time (scenario time = clock - T0).
    """

    def __init__(self, truth: Any, clock: Clock, track_id: int = 7, end_s: float = 1e9) -> None:
        self.truth, self.clock, self.track_id, self.end_s = truth, clock, track_id, end_s
        self.commits = _Commits()
        self.tracker = self

    def tracks(self, *, include_ended: bool = True, **_: Any) -> list[Track]:
        t_now = self.clock() - T0
        if t_now > self.end_s and not include_ended:
            return []
        t = np.asarray(self.truth.t_s)
        sel = np.flatnonzero((t <= min(t_now, self.end_s) + 1e-9) & (t >= t_now - 3.0))
        if len(sel) == 0:
            return []
        p = np.asarray(self.truth.p_enu)
        points = tuple(TrackPoint(T0 + float(t[i]), p[i], ("x",), (int(i),)) for i in sel)
        return [Track(self.track_id, "vehicle", points)]
