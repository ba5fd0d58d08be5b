"""Stream messages -> CoT events (tracks and markers).

A ``track_update`` becomes one event at the track's newest point: ``uid``
``demtrack.<store>.track.<id>``, the type of its class, ``time`` the point's moment and
``stale`` that plus ``track_stale_s`` (an ended track goes stale at its last point, so
TAK greys it at once). CE/LE come from the covariances of the fixes behind the point:
the ``fix`` messages that precede it in the stream are remembered (a bounded cache) and,
per detection, the terrain hit nearest the point is taken; several detections (cameras)
are combined as independent measurements (information sum). LE is the vertical 1-sigma
of a point on the DEM (:func:`~demtrack.core.io.cot.terrain_vertical_variance_m2`:
the slope times the horizontal error plus the DEM's own variance there). Course and speed
come from the newest two points. A ``marker`` (``add``/``update``) becomes a spot map
point ``b-m-p-s-m`` stamped with the moment it is sent (its own time goes in the
remarks, beside its MGRS), stale after ``marker_stale_s``; a ``delete`` is CoT's
``t-x-d-d`` naming the marker's uid.
"""

from __future__ import annotations

import math
import time
from collections import OrderedDict
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from demtrack.core.errors import DemtrackError
from demtrack.core.geo.grid_ref import mgrs_of
from demtrack.core.io.cot import (
    COT_UNKNOWN_M,
    CotEvent,
    circular_error_m,
    cot_type_of,
    linear_error_m,
    terrain_vertical_variance_m2,
)
from demtrack.core.terrain.dem import Dem

__all__ = ["CotBuilder", "fused_covariance"]

_DELETE_TYPE = "t-x-d-d"


def fused_covariance(covs: Sequence[np.ndarray]) -> np.ndarray | None:
    """The covariance of independent measurements of one point combined (information sum).

    ``covs``: 2x2 covariances (m^2); None when there are none or any is singular.
    """
    if not covs:
        return None
    if len(covs) == 1:
        return np.asarray(covs[0], dtype=np.float64)
    try:
        info = sum(np.linalg.inv(np.asarray(c, dtype=np.float64)) for c in covs)
        return np.asarray(np.linalg.inv(info))
    except np.linalg.LinAlgError:
        return None


def _mgrs(lat: float, lon: float) -> str:
    try:
        return mgrs_of(lat, lon)
    except DemtrackError:
        return ""


class CotBuilder:
    """Turns published stream messages into CoT events.

    Parameters
    ----------
    store_id : str
        The store's identity (part of every uid: two databases never share one).
    dem : Dem
        The site DEM (slope and variance for LE).
    track_stale_s, marker_stale_s : float
        How long a track's and a marker's event stays fresh (s).
    max_fixes : int
        Fix covariances remembered (the newest).
    clock : callable
        UNIX seconds now (markers are stamped with it).
    """

    def __init__(
        self,
        store_id: str,
        dem: Dem,
        track_stale_s: float = 60.0,
        marker_stale_s: float = 86_400.0,
        max_fixes: int = 20_000,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.prefix = f"demtrack.{store_id[:12]}"
        self.dem = dem
        self.track_stale_s = track_stale_s
        self.marker_stale_s = marker_stale_s
        self.max_fixes = max_fixes
        self.clock = clock
        self.fixes: OrderedDict[int, list[tuple[float, float, np.ndarray]]] = OrderedDict()
        self.last_point: dict[int, dict[str, Any]] = {}

    # ------------------------------------------------------------------ messages
    def events(self, message: dict[str, Any]) -> list[CotEvent]:
        """The CoT events of one stream message (none for most kinds)."""
        kind = message.get("type")
        if kind == "fix":
            self._remember(message["fix"])
            return []
        if kind == "track_update":
            ev = self._track(message["track"])
            return [] if ev is None else [ev]
        if kind == "marker":
            return [self._marker(message)]
        return []

    def _remember(self, fix: dict[str, Any]) -> None:
        hits = []
        for h in fix.get("hits", []) + ([fix["road_hit"]] if fix.get("road_hit") else []):
            cov = h.get("cov_en_m2")
            c = np.asarray(cov, dtype=np.float64) if cov else np.eye(2) * h["sigma_m"] ** 2
            hits.append((float(h["e_m"]), float(h["n_m"]), c))
        self.fixes[int(fix["detection_id"])] = hits
        while len(self.fixes) > self.max_fixes:
            self.fixes.popitem(last=False)

    def point_covariance(self, point: dict[str, Any]) -> np.ndarray | None:
        """The horizontal covariance (m^2) of a track point from its fixes, or None."""
        covs = []
        for det in point.get("detection_ids", []):
            hits = self.fixes.get(int(det))
            if not hits:
                continue
            e, n = point["e_m"], point["n_m"]
            covs.append(min(hits, key=lambda h: (h[0] - e) ** 2 + (h[1] - n) ** 2)[2])
        return fused_covariance(covs)

    def errors_m(self, point: dict[str, Any]) -> tuple[float, float]:
        """``(ce, le)`` of a track point (m); CoT's unknown where no fix is known."""
        cov = self.point_covariance(point)
        if cov is None:
            return COT_UNKNOWN_M, COT_UNKNOWN_M
        ce = circular_error_m(cov)
        e, n = np.array([point["e_m"]]), np.array([point["n_m"]])
        gx, gy = self.dem.gradient(e, n)
        var_dem = float(self.dem.sample_variance(e, n)[0])
        var_u = terrain_vertical_variance_m2(cov, (float(gx[0]), float(gy[0])), var_dem)
        return ce, linear_error_m(var_u)

    def _track(self, track: dict[str, Any]) -> CotEvent | None:
        points = track.get("points") or []
        if not points:
            return None
        tid = int(track["id"])
        p = points[-1]
        before = points[-2] if len(points) > 1 else self.last_point.get(tid)
        self.last_point[tid] = p
        if not track.get("live", True):
            self.last_point.pop(tid, None)
        course = speed = None
        if before is not None and p["t_s"] > before["t_s"]:
            de, dn = p["e_m"] - before["e_m"], p["n_m"] - before["n_m"]
            speed = math.hypot(de, dn) / (p["t_s"] - before["t_s"])
            # site-frame north is true north at the anchor (the site is small)
            course = math.degrees(math.atan2(de, dn)) % 360.0
        ce, le = self.errors_m(p)
        t = float(p["t_s"])
        stale = t + self.track_stale_s if track.get("live", True) else t
        lat, lon = float(p["lat_deg"]), float(p["lon_deg"])
        ref = _mgrs(lat, lon)
        sensors = ", ".join(p.get("sensors", []))
        return CotEvent(
            uid=f"{self.prefix}.track.{tid}",
            type=cot_type_of(track["cls"]),
            how="m-f",
            time_s=t,
            start_s=t,
            stale_s=stale,
            lat_deg=lat,
            lon_deg=lon,
            hae_m=float(p["h_m"]),
            ce_m=ce,
            le_m=le,
            callsign=f"{track['cls']} {tid}",
            remarks=f"MGRS {ref}; sensors {sensors}" if ref else f"sensors {sensors}",
            course_deg=course,
            speed_mps=speed,
        )

    def _marker(self, message: dict[str, Any]) -> CotEvent:
        now = float(self.clock())
        uid = f"{self.prefix}.marker.{int(message['id'])}"
        m = message.get("marker")
        if message.get("action") == "delete" or m is None:
            # lat/lon of a delete are not read by TAK; the link names what goes
            return CotEvent(
                uid=f"{uid}.delete",
                type=_DELETE_TYPE,
                how="h-e",
                time_s=now,
                start_s=now,
                stale_s=now + 60.0,
                lat_deg=0.0,
                lon_deg=0.0,
                hae_m=0.0,
                remarks=f"delete {uid}",
                link_uid=uid,
            )
        note = f"; {m['note']}" if m.get("note") else ""
        return CotEvent(
            uid=uid,
            type=cot_type_of("marker"),
            how="h-e",
            time_s=now,
            start_s=now,
            stale_s=now + self.marker_stale_s,
            lat_deg=float(m["lat_deg"]),
            lon_deg=float(m["lon_deg"]),
            hae_m=float(m["h_m"]),
            callsign=str(m.get("name") or f"M{message['id']}"),
            remarks=f"MGRS {m.get('mgrs', '')}; marked {m.get('time_utc', '')}{note}",
        )
