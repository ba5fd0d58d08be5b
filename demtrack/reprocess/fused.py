"""Dask's tasks: a tracking job geolocates its own detections, then tracks them.

The local engine geolocates the plan's parts and hands their fixes to the tracking jobs;
on a cluster that costs a task per part, the fixes shipped from the part's worker to each
job's (a part reaches across several jobs), and jobs waiting for parts. Here a job's task
runs ``geolocate_part`` on exactly the detections its segments hold (each detection is in
one segment: groups share no sensor and segments cut a group's time line), and a chained
segment's window task on the window's detections, then tracks them as
:mod:`.tasks` does. The fixes are those of any other partition, bit for bit (geolocation
does not depend on how detections are batched: ``tests/reprocess/test_windows.py``;
each sensor is geolocated apart, as a part is, so one sensor's lone detection takes a
part's path for one detection), so
the outputs are the local engine's. Rows of sensors in no group (none today: every
present sensor is in a group) are geolocated by their plan parts alone.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pyarrow as pa

from .plan import Plan
from .tasks import (
    GeoResult,
    WindowResult,
    geolocate_part,
    site_at,
    track_segments,
    track_window,
)

__all__ = ["JobRows", "job_rows", "track_job", "track_window_rows", "warm_up"]

_ALL = (-np.inf, np.inf)


@dataclass(frozen=True)
class JobRows:
    """Row indices (table order) of each segment, and the parts of sensors in no group."""

    segments: tuple[np.ndarray, ...]
    loose_parts: tuple[int, ...]


def job_rows(plan: Plan, table: pa.Table) -> JobRows:
    """The canonical table's rows of every segment of ``plan`` (module notes)."""
    t = table["t_s"].to_numpy(zero_copy_only=False)
    sensor = np.array(table["sensor"].to_pylist(), dtype=object)
    by_group: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    segs: list[np.ndarray] = []
    for seg in plan.segments:
        if seg.group not in by_group:
            rows = np.flatnonzero(np.isin(sensor, list(plan.groups[seg.group])))
            by_group[seg.group] = (rows, t[rows])
        rows, t_g = by_group[seg.group]
        a = int(np.searchsorted(t_g, seg.t_first, side="left"))
        b = int(np.searchsorted(t_g, seg.t_last, side="right"))
        segs.append(rows[a:b])
    grouped = {sid for g in plan.groups for sid in g}
    loose = tuple(k for k, p in enumerate(plan.parts) if p.sensor not in grouped)
    return JobRows(tuple(segs), loose)


def _geolocate(site_dir: str, rows: pa.Table, det_ids: np.ndarray) -> GeoResult:
    """``geolocate_part`` per sensor, as the plan's parts are (one sensor each).

    So a sensor with a single detection here takes the part's path for one detection
    (numpy's single-row product: :func:`.tasks.geolocate_part`), whatever else the rows hold.
    """
    sensor = np.array(rows["sensor"].to_pylist(), dtype=object)
    results = []
    for sid in sorted(set(sensor.tolist())):
        mine = np.flatnonzero(sensor == sid)
        results.append(geolocate_part(site_dir, rows.take(mine), det_ids[mine]))
    return GeoResult.merged(results)


def track_job(
    site_dir: str,
    method: str,
    specs: Sequence[tuple[int, float, float]],
    rows: pa.Table,
    det_ids: np.ndarray,
) -> tuple[GeoResult, list[list]]:
    """Geolocate a job's detections and track its one-window segments (``specs``)."""
    geo = _geolocate(site_dir, rows, det_ids)
    return geo, track_segments(site_dir, method, specs, [geo])


def track_window_rows(
    site_dir: str,
    method: str,
    seed: int,
    previous: tuple[GeoResult, WindowResult] | None,
    rows: pa.Table,
    det_ids: np.ndarray,
    window: tuple[float, float],
    last: bool,
    bounds: tuple[float, float],
) -> tuple[GeoResult, WindowResult]:
    """Geolocate one window's detections and feed them to the segment's tracker."""
    geo = _geolocate(site_dir, rows, det_ids)
    prev = None if previous is None else previous[1]
    return geo, track_window(site_dir, method, seed, prev, [geo], window, last, bounds)


def warm_up(site_dir: str, method: str, rows: pa.Table) -> int:
    """Load the site, numba's kernels and the tracker here (a few rows, run and dropped).

    What every engine runs before it is timed (``demtrack bench reprocess``), so that no
    timing holds a process's first geolocation and tracking. Returns the rows it ran.
    """
    site_at(site_dir)
    ids = np.arange(rows.num_rows, dtype=np.int64)
    if rows.num_rows:
        track_job(site_dir, method, [(0, *_ALL)], rows, ids)
    return rows.num_rows
