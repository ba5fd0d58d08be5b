"""The reprocessing plan: geolocation parts, tracking segments and windows, seeds.

Everything here is a function of the archive, the site's sensor groups and the
settings - never of the engine or the number of workers:

* a **segment** is a stretch of one group's time line between *quiet gaps*, times
  longer than ``quiet_s`` in which none of the group's sensors detected anything
  (default 60 s, more than a track's coasting plus its re-acquisition window, so every
  track has ended at a gap). Each segment is tracked by a fresh tracker seeded from the
  group and the segment (:func:`segment_seed`); segments run in parallel;
* a segment is tracked in **windows** of ``window_s`` run in sequence, each handing the
  tracker's exact state (tracks, buffered fixes, random generator) to the next, so the
  window length changes nothing (``tests/reprocess/test_windows.py``);
* a geolocation **part** is one sensor's detections within one ``chunk_s`` chunk of
  UTC time (chunks start at multiples of ``chunk_s`` after the UNIX epoch);
* a tracking **job** is one task's work: a segment longer than one window alone (its
  windows chained, one task each), or consecutive one-window segments of a group
  packed until they hold ``job_rows`` detections (1,000: a few tasks per worker even
  for a small archive; they are tracked one after the
  other, each by its own tracker, so packing changes nothing but the task count).
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from demtrack.core.errors import InputFileError

__all__ = ["GeoPart", "Plan", "Segment", "make_plan", "segment_seed", "split_quiet"]

#: Detections a job of one-window segments holds at least (unless the group ends).
JOB_ROWS = 1000


@dataclass(frozen=True)
class GeoPart:
    """One geolocation task: rows of the canonical table (one sensor, one time chunk)."""

    key: str
    sensor: str
    rows: np.ndarray
    t_min: float
    t_max: float


@dataclass(frozen=True)
class Segment:
    """One quiet-bounded stretch of a group's time line and its windows.

    ``windows`` are ``(t_lo, t_hi)``, half-open, covering ``[t_first, t_last]``; the last
    one is closed. ``parts`` index :attr:`Plan.parts`.
    """

    group: int
    index: int
    t_first: float
    t_last: float
    seed: int
    windows: tuple[tuple[float, float], ...]
    parts: tuple[int, ...]

    @property
    def key(self) -> str:
        """Task key prefix ``g<group>-s<segment>``."""
        return f"g{self.group}-s{self.index}"


@dataclass(frozen=True)
class Plan:
    """Every task of a run (see the module notes); ``jobs`` index :attr:`segments`."""

    groups: tuple[tuple[str, ...], ...]
    parts: tuple[GeoPart, ...]
    segments: tuple[Segment, ...]
    jobs: tuple[tuple[int, ...], ...]
    quiet_s: float
    window_s: float
    chunk_s: float


def segment_seed(group: tuple[str, ...], t_first: float) -> int:
    """The tracker seed of a segment: from its group's sensors and its first time only."""
    text = f"{'+'.join(group)}@{float(t_first)!r}".encode()
    return int.from_bytes(hashlib.sha256(text).digest()[:4], "big")


def split_quiet(t_sorted: np.ndarray, quiet_s: float) -> list[tuple[int, int]]:
    """Row ranges ``[a, b)`` of sorted times split where the step exceeds ``quiet_s``."""
    if len(t_sorted) == 0:
        return []
    cut = np.flatnonzero(np.diff(t_sorted) > quiet_s) + 1
    edges = [0, *cut.tolist(), len(t_sorted)]
    return list(zip(edges[:-1], edges[1:], strict=True))


def _windows(t_first: float, t_last: float, window_s: float) -> tuple[tuple[float, float], ...]:
    n = max(1, int(np.floor((t_last - t_first) / window_s)) + 1)
    edges = [t_first + k * window_s for k in range(n)] + [np.inf]
    return tuple(zip(edges[:-1], edges[1:], strict=True))


def _parts(t: np.ndarray, sensor: np.ndarray, chunk_s: float) -> list[GeoPart]:
    """One part per (sensor, UTC chunk) holding rows (rows of each in table order)."""
    chunk = np.floor(t / chunk_s).astype(np.int64)
    order = np.lexsort((chunk, sensor.astype(str)))
    key_s, key_c = sensor[order], chunk[order]
    cut = np.flatnonzero((key_s[1:] != key_s[:-1]) | (key_c[1:] != key_c[:-1])) + 1
    parts = []
    for a, b in zip([0, *cut.tolist()], [*cut.tolist(), len(order)], strict=True):
        rows = np.sort(order[a:b])
        sid, c = str(key_s[a]), int(key_c[a])
        parts.append(GeoPart(f"geo-{sid}-c{c}", sid, rows, float(t[rows[0]]), float(t[rows[-1]])))
    return parts


def make_plan(
    table: pa.Table,
    groups: list[tuple[str, ...]],
    *,
    quiet_s: float = 60.0,
    window_s: float = 3600.0,
    chunk_s: float = 600.0,
    job_rows: int = JOB_ROWS,
) -> Plan:
    """Parts, segments, windows and jobs of a canonical archive table (module notes)."""
    for name, value in (("quiet_s", quiet_s), ("window_s", window_s), ("chunk_s", chunk_s)):
        if not (np.isfinite(value) and value > 0):
            raise InputFileError(f"{name} must be a positive number of seconds, got {value}")
    t = table["t_s"].to_numpy(zero_copy_only=False)
    sensor = np.array(table["sensor"].to_pylist(), dtype=object)
    parts = _parts(t, sensor, chunk_s) if len(t) else []
    by_sensor: dict[str, list[int]] = {}
    for k, part in enumerate(parts):
        by_sensor.setdefault(part.sensor, []).append(k)
    segments: list[Segment] = []
    jobs: list[tuple[int, ...]] = []
    for g, members in enumerate(groups):
        rows_g = np.flatnonzero(np.isin(sensor, list(members)))
        if not len(rows_g):
            continue
        mine = [k for sid in members for k in by_sensor.get(sid, [])]
        packed: list[int] = []
        n_packed = 0
        for s, (a, b) in enumerate(split_quiet(t[rows_g], quiet_s)):
            t0, t1 = float(t[rows_g[a]]), float(t[rows_g[b - 1]])
            overlapping = tuple(k for k in mine if parts[k].t_max >= t0 and parts[k].t_min <= t1)
            windows = _windows(t0, t1, window_s)
            index = len(segments)
            segments.append(
                Segment(
                    g, s, t0, t1, segment_seed(members, t0), windows, tuple(sorted(overlapping))
                )
            )
            if len(windows) > 1:
                jobs.append((index,))
                continue
            packed.append(index)
            n_packed += b - a
            if n_packed >= job_rows:
                jobs.append(tuple(packed))
                packed, n_packed = [], 0
        if packed:
            jobs.append(tuple(packed))
    return Plan(
        tuple(groups), tuple(parts), tuple(segments), tuple(jobs), quiet_s, window_s, chunk_s
    )
