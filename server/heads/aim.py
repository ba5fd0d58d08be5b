"""Where to point a head: a ground point or a live track, to pan and tilt.

:func:`aim_pan_tilt` is the inverse pointing of the pan-tilt head model
(:func:`demtrack.core.camera.pointing.point_head_at`); :func:`check_ground_point` adds the
checks an operator's "look here" needs (on the DEM, a clear sight line, inside the tilt
range: :func:`~demtrack.core.camera.pointing.aim_check`), each failure one line.
:func:`track_motion` reads the pipeline's newest estimate of a track (position and
velocity) without holding up ingest, and :func:`los_exit_s` says when
a head that follows a target will lose its line of sight to it (the target's path
extrapolated as the hand-off predictor does: along its road, or straight).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from demtrack.core.camera.head_motion import SlewLimits
from demtrack.core.camera.pointing import aim_check, point_head_at
from demtrack.core.errors import DemtrackError
from demtrack.core.site.folder import Sensor, Site
from demtrack.core.tracking.roadfollow import follow_road
from demtrack.core.visibility.viewshed import target_visible_fraction

__all__ = [
    "AimError",
    "TrackMotion",
    "aim_pan_tilt",
    "check_ground_point",
    "los_exit_s",
    "sensor_at",
    "track_motion",
]

#: Height (m) above a ground point that "look here" aims at (aim_check's default).
LOOK_HEIGHT_M = 1.0


class AimError(DemtrackError, ValueError):
    """A point a head cannot be pointed at (off the DEM, hidden, outside the tilt range)."""


def aim_pan_tilt(
    sensor: Sensor, p_enu: np.ndarray, hfov_deg: float | None = None
) -> tuple[float, float]:
    """Pan and tilt (degrees) that centre ``p_enu`` (site frame, m) in ``sensor``'s image.

    :func:`~demtrack.core.camera.pointing.point_head_at` at the zoom ``hfov_deg`` (None:
    the calibrated lens), through the sensor's zoom table when it has one.
    """
    return point_head_at(sensor.head, p_enu, hfov_deg=hfov_deg, zoom=getattr(sensor, "zoom", None))


def sensor_at(sensor: Sensor, pan_deg: float, tilt_deg: float) -> Sensor:
    """``sensor`` turned to another pan and tilt (its camera follows)."""
    return replace(sensor, pan_deg=float(pan_deg), tilt_deg=float(tilt_deg))


def check_ground_point(
    site: Site,
    sensor: Sensor,
    e_m: float,
    n_m: float,
    u_m: float | None,
    limits: SlewLimits,
    hfov_deg: float | None = None,
) -> tuple[np.ndarray, float, float]:
    """``(p_enu, pan_deg, tilt_deg)`` for a ground point, or :class:`AimError` saying why not.

    :func:`~demtrack.core.camera.pointing.aim_check`: ``u_m`` ``None`` takes the DEM's
    height there; the sight line to a point 1 m above the ground (the middle of what
    stands there) must clear the terrain, and the tilt must lie in the head's range.
    """
    where = [e_m, n_m] if u_m is None else [e_m, n_m, u_m]
    check = aim_check(
        sensor.head,
        where,
        site.dem,
        slew_limits=limits.to_dict(),
        hfov_deg=hfov_deg,
        zoom=getattr(sensor, "zoom", None),
    )
    if not check.visible:
        raise AimError(
            f"sensor {sensor.id} cannot look at ({e_m:.1f}, {n_m:.1f}) m: {check.reason}"
        )
    p = np.array(check.target_enu, dtype=np.float64) - [0.0, 0.0, LOOK_HEIGHT_M]
    return p, check.pan_deg, check.tilt_deg


@dataclass(frozen=True, eq=False)
class TrackMotion:
    """A track's newest estimate: time (s), position (m) and velocity (m/s), site frame."""

    track_id: int
    t_s: float
    p_enu: np.ndarray
    v_enu: np.ndarray
    ended: bool = False

    def at(self, t_s: float) -> np.ndarray:
        """Position extrapolated to ``t_s`` at constant velocity (m)."""
        return self.p_enu + self.v_enu * (float(t_s) - self.t_s)


def track_motion(
    pipeline: Any, track_id: int, window_s: float = 1.0, wait_s: float = 0.05
) -> TrackMotion | None:
    """The pipeline's newest estimate of ``track_id``; None if unknown or busy.

    Velocity is the mean over the last ``window_s`` seconds of points. The pipeline's lock
    is tried for ``wait_s`` only (50 ms): a controller tick never waits for a long ingest.
    """
    lock = pipeline.commits.lock
    if not lock.acquire(timeout=wait_s):
        return None
    try:
        live = {t.id: t for t in pipeline.tracker.tracks(include_ended=False)}
        track = live.get(track_id)
        ended = track is None
        if track is None:
            track = next((t for t in pipeline.tracker.tracks() if t.id == track_id), None)
    finally:
        lock.release()
    if track is None or not track.points:
        return None
    t, p = track.t_s, track.p_enu
    k = int(np.searchsorted(t, t[-1] - window_s))
    k = min(k, len(t) - 2) if len(t) > 1 else 0
    v = (p[-1] - p[k]) / (t[-1] - t[k]) if t[-1] > t[k] else np.zeros(3)
    v = np.array([v[0], v[1], 0.0])
    return TrackMotion(track_id, float(t[-1]), np.array(p[-1]), v, ended)


def los_exit_s(
    site: Site,
    sensor: Sensor,
    motion: TrackMotion,
    t_s: float,
    *,
    height_m: float = 1.5,
    horizon_s: float = 20.0,
    dt_s: float = 0.5,
    min_fraction: float = 0.5,
    max_range_m: float = 1000.0,
    min_loss_s: float = 2.0,
) -> float | None:
    """Seconds from ``t_s`` until ``sensor`` loses its sight line to the target (None: not soon).

    A loss counts only when it lasts ``min_loss_s`` (a pole or a crest the target passes
    behind for a moment is no reason to hand it over); one running past the horizon counts.
    """
    times = np.arange(0.0, horizon_s + 1e-9, dt_s)
    p0 = motion.at(t_s)
    xy = None
    if site.roads is not None and len(site.roads):
        xy = follow_road(site.roads.lines, p0, motion.v_enu, times, 5.0)
    if xy is None:
        xy = p0[None, :2] + times[:, None] * motion.v_enu[None, :2]
    z = site.dem.sample(xy[:, 0], xy[:, 1])
    path = np.column_stack([xy, np.nan_to_num(z, nan=float(p0[2]))])
    frac = target_visible_fraction(
        site.dem, sensor.camera, path, height_m, max_range_m=max_range_m, in_view=False
    )
    hidden = frac < min_fraction
    n = max(1, int(math.ceil(min_loss_s / dt_s - 1e-9)))
    for i in np.flatnonzero(hidden):
        if hidden[i : i + n].all():
            return float(times[i])
    return None
