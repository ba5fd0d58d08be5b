"""What a reprocessing task runs: one geolocation part, one tracking window.

Plain functions of picklable values, so the local engine calls them directly and Dask
ships them to workers. A worker loads a site once (:func:`site_at`, cached per process).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np
import pyarrow as pa

from demtrack.core.site.folder import Site, load_site
from demtrack.core.tracking import Track, Tracker, TrackerConfig, build_tracker

from .archive import detections_of
from .fix_columns import FixColumns

__all__ = [
    "GeoResult",
    "WindowResult",
    "geolocate_part",
    "segment_tracks",
    "site_at",
    "track_window",
]


@functools.lru_cache(maxsize=4)
def site_at(site_dir: str) -> Site:
    """The site folder ``site_dir``, loaded once per process."""
    return load_site(site_dir)


@dataclass(frozen=True)
class GeoResult:
    """A part's fixes and what build_fixes skipped (counts by reason)."""

    fixes: FixColumns
    counts: dict[str, int] = field(default_factory=dict)

    @classmethod
    def merged(cls, results: Sequence[GeoResult]) -> GeoResult:
        """One result of several: their fixes in the given order, their counts summed."""
        counts: dict[str, int] = {}
        for r in results:
            for k, v in r.counts.items():
                counts[k] = counts.get(k, 0) + v
        return cls(FixColumns.concat([r.fixes for r in results]), counts)


def geolocate_part(site_dir: str, rows: pa.Table, det_ids: np.ndarray) -> GeoResult:
    """Geolocate archive rows (one sensor, in time order); ``det_ids`` are their ids.

    Inline poses (the rows' ``pan_deg``/``tilt_deg``/``hfov_deg``) geolocate their own
    detection, as in ``demtrack track``.
    """
    from demtrack.core.camera.pose_series import PoseSample
    from demtrack.core.geolocation.fix_builder import build_fixes
    from demtrack.core.io.detections import IngestReport
    from demtrack.core.io.pose_io import poses_from_detections

    site = site_at(site_dir)
    detections, inline = detections_of(rows)
    samples: dict[str, list[PoseSample]] = {}
    for i, (pan, tilt, hfov) in sorted(inline.items()):
        det = detections[i]
        samples.setdefault(det.sensor, []).append(PoseSample(det.t_s, pan, tilt, hfov))
    report = IngestReport(0, 0, poses={s: tuple(v) for s, v in samples.items()})
    poses = poses_from_detections(report) if samples else None
    if len(detections) == 1:
        # numpy multiplies a single row by a matrix on another BLAS path (gemv, not gemm)
        # whose last bits differ; a batch of two (the detection twice) gives the bits the
        # detection gets in any larger batch, so a part's size changes nothing.
        fixes, fix_report = build_fixes(site, detections * 2, poses=poses)
        fixes = [f for f in fixes if f.detection_index == 0]
        fix_report = replace(
            fix_report,
            n_detections=1,
            n_fixes=len(fixes),
            counts={k: v // 2 for k, v in fix_report.counts.items()},
        )
    else:
        fixes, fix_report = build_fixes(site, detections, poses=poses)
    counts = {k: int(v) for k, v in fix_report.counts.items() if v}
    return GeoResult(FixColumns.from_fixes(fixes, det_ids), counts)


@dataclass
class WindowResult:
    """A window's hand-off: the tracker (None after the last window) and finished tracks.

    ``tracks`` are the segment's tracks that can no longer change (ended and past the
    re-acquisition window), with the tracker's own ids; after the last window, all the
    rest.
    """

    tracker: Tracker | None
    tracks: list[Track]


def _new_tracker(site: Site, method: str, seed: int) -> Tracker:
    return build_tracker(method, roads=site.roads, config=TrackerConfig(seed=seed))


def track_window(
    site_dir: str,
    method: str,
    seed: int,
    previous: WindowResult | None,
    parts: Sequence[GeoResult],
    window: tuple[float, float],
    last: bool,
    bounds: tuple[float, float] = (-np.inf, np.inf),
) -> WindowResult:
    """Feed one window's fixes to a segment's tracker.

    The window's fixes are those of ``parts`` with ``window[0] <= t < window[1]`` and
    ``bounds[0] <= t <= bounds[1]`` (the segment's first and last times). ``previous`` is
    the window before's result (None for a segment's first window: a fresh tracker
    seeded with ``seed``). The tracker continues exactly where it was: the same object
    state, random generator included, as one long run.
    """
    site = site_at(site_dir)
    tracker = _new_tracker(site, method, seed) if previous is None else previous.tracker
    if tracker is None:
        raise ValueError("internal: a window after the segment's last one")
    cols = FixColumns.concat([p.fixes for p in parts])
    lo, hi = max(window[0], bounds[0]), window[1]
    inside = np.flatnonzero((cols.t_s >= lo) & (cols.t_s < hi) & (cols.t_s <= bounds[1]))
    cols = cols.take(inside).sorted()
    for fix in cols.to_fixes():
        tracker.update(fix, index=fix.detection_index)
    if last:
        return WindowResult(None, tracker.finish())
    # Tracks that can no longer change leave the state, so what is handed on stays small.
    held = {t.id: t for t in tracker.tracks()}
    done = [held[i] for i in sorted(tracker.drop_ended(np.inf)) if i in held]
    return WindowResult(tracker, done)


def track_segments(
    site_dir: str,
    method: str,
    specs: Sequence[tuple[int, float, float]],
    parts: Sequence[GeoResult],
) -> list[list[Track]]:
    """Track one-window segments one after the other, each with its own fresh tracker.

    ``specs`` are ``(seed, t_first, t_last)`` per segment; returns each one's tracks.
    """
    return [
        track_window(site_dir, method, seed, None, parts, (-np.inf, np.inf), True, (a, b)).tracks
        for seed, a, b in specs
    ]


def segment_tracks(results: Sequence[WindowResult]) -> list[Track]:
    """All tracks of a segment's window results, by the tracker's id."""
    out: dict[int, Track] = {}
    for r in results:
        for t in r.tracks:
            out[t.id] = t
    return [out[k] for k in sorted(out)]
