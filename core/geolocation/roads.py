"""Road network and the paper's road rule for geolocating vehicles.

Collins et al. (1998, section 4) note that a vehicle is on a road: project the viewing ray
and the road centre lines to the ground plane, intersect them, and among the
intersections pick the one where the DEM elevation is closest to the ray's height,
``argmin |DEM(x, y) - z_ray(x, y)|``. Road lines are indexed with a shapely STRtree so a
ray only meets the segments near it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import shapely
from shapely import LineString, STRtree

from ..errors import InputFileError

__all__ = ["RoadCandidate", "RoadChoices", "RoadNetwork"]


def _clip_to_box(
    start: np.ndarray, stop: np.ndarray, box: tuple[float, float, float, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Segments ``start -> stop`` (k, 2) clipped to ``box`` (Liang-Barsky).

    Returns the clipped ends and a mask of the segments that touch the box (the ends
    of the others are meaningless). A segment inside the box is returned bit for bit.
    """
    lo = np.array(box[:2])
    hi = np.array(box[2:])
    step = stop - start
    t0 = np.zeros(len(start))
    t1 = np.ones(len(start))
    inside = np.ones(len(start), bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for a in range(2):
            flat = step[:, a] == 0.0
            inside &= ~flat | ((start[:, a] >= lo[a]) & (start[:, a] <= hi[a]))
            ta = (lo[a] - start[:, a]) / step[:, a]
            tb = (hi[a] - start[:, a]) / step[:, a]
            t0 = np.where(flat, t0, np.maximum(t0, np.minimum(ta, tb)))
            t1 = np.where(flat, t1, np.minimum(t1, np.maximum(ta, tb)))
    over = inside & (t0 <= t1)
    new_start = np.where((t0 > 0.0)[:, None], start + t0[:, None] * step, start)
    new_stop = np.where((t1 < 1.0)[:, None], start + t1[:, None] * step, stop)
    return new_start, new_stop, over


@dataclass(frozen=True)
class RoadCandidate:
    """One crossing of a viewing ray's ground track with a road centre line.

    Attributes
    ----------
    p_enu : ndarray, shape (3,)
        Point on the road (x, y) at the DEM elevation (z), site frame (m).
    range_m : float
        Distance along the (unit) ray to the point above/below the crossing.
    vertical_gap_m : float
        ``|DEM(x, y) - z_ray|`` at the crossing (m): the quantity the rule minimises.
    road_index : int
        Index of the road line in the network.
    """

    p_enu: np.ndarray
    range_m: float
    vertical_gap_m: float
    road_index: int


@dataclass(frozen=True, eq=False)
class RoadChoices:
    """The road rule's answer for each ray of a batch (:meth:`RoadNetwork.best_candidates`).

    Attributes
    ----------
    p_enu : ndarray, shape (n, 3)
        Chosen road point (x, y on the road, z the DEM elevation), site frame (m); NaN
        rows where a ray has no answer.
    vertical_gap_m : ndarray, shape (n,)
        ``|DEM(x, y) - z_ray|`` at the chosen crossing (m); NaN where none.
    road_index : ndarray, int64, shape (n,)
        Index of the chosen road line; -1 where none.
    """

    p_enu: np.ndarray
    vertical_gap_m: np.ndarray
    road_index: np.ndarray

    @property
    def found(self) -> np.ndarray:
        """Boolean mask of rays with an answer, shape (n,)."""
        return self.road_index >= 0


@dataclass(frozen=True, eq=False)
class RoadNetwork:
    """Road centre lines in the site frame.

    Parameters
    ----------
    lines : sequence of shapely.LineString
        Centre lines with x east, y north (m).
    names : sequence of str, optional
    widths_m : sequence of float, optional
        Carriageway widths (m), for display and snapping.
    """

    lines: tuple[LineString, ...]
    names: tuple[str, ...] = ()
    widths_m: tuple[float, ...] = ()
    _tree: STRtree = field(init=False, repr=False)
    _segments: np.ndarray = field(init=False, repr=False)
    _segment_road: np.ndarray = field(init=False, repr=False)
    _segment_tree: STRtree = field(init=False, repr=False)
    _segment_xy: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        lines = tuple(self.lines)
        for i, line in enumerate(lines):
            if not isinstance(line, LineString) or line.is_empty or len(line.coords) < 2:
                raise InputFileError(f"road {i} is not a line with at least two points")
            if not np.isfinite(shapely.get_coordinates(line)).all():
                raise InputFileError(f"road {i} has non-finite coordinates")
        names = tuple(self.names) or tuple(f"road {i}" for i in range(len(lines)))
        widths = tuple(float(w) for w in self.widths_m) or (6.0,) * len(lines)
        if len(names) != len(lines):
            raise InputFileError(f"{len(names)} road names given for {len(lines)} roads")
        if len(widths) != len(lines):
            raise InputFileError(f"{len(widths)} road widths given for {len(lines)} roads")
        object.__setattr__(self, "lines", lines)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "widths_m", widths)
        object.__setattr__(self, "_tree", STRtree(lines))
        # Every two-vertex segment on its own, for the bulk road rule: a ray's ground
        # track then meets only the few short segments near it, not whole polylines.
        xy, owner = shapely.get_coordinates(np.asarray(lines, dtype=object), return_index=True)
        same = owner[1:] == owner[:-1]
        starts = np.flatnonzero(same)
        seg_xy = np.stack([xy[starts], xy[starts + 1]], axis=1)
        segments = shapely.linestrings(seg_xy)
        object.__setattr__(self, "_segment_xy", seg_xy.reshape(-1, 2, 2))
        object.__setattr__(self, "_segments", np.asarray(segments, dtype=object).reshape(-1))
        object.__setattr__(self, "_segment_road", owner[starts].astype(np.int64))
        object.__setattr__(self, "_segment_tree", STRtree(self._segments))

    @classmethod
    def from_coordinates(
        cls, coords: Sequence[np.ndarray], names: Sequence[str] = (), widths_m: Sequence[float] = ()
    ) -> RoadNetwork:
        """Build from arrays of ``(k, 2)`` (or ``(k, 3)``, z dropped) site-frame vertices.

        Raises
        ------
        InputFileError
            If a vertex array is not ``(k >= 2, 2 or 3)`` of finite numbers.
        """
        lines = []
        for i, c in enumerate(coords):
            # Checked here: shapely would fail with a GEOS message on one vertex.
            xy = np.asarray(c, dtype=np.float64)
            if xy.ndim != 2 or xy.shape[0] < 2 or xy.shape[1] not in (2, 3):
                raise InputFileError(
                    f"road {i}: vertices must have shape (k >= 2, 2 or 3), got {xy.shape}"
                )
            if not np.isfinite(xy[:, :2]).all():
                raise InputFileError(f"road {i} has non-finite coordinates")
            lines.append(LineString(xy[:, :2]))
        return cls(tuple(lines), tuple(names), tuple(widths_m))

    def __len__(self) -> int:
        return len(self.lines)

    def ray_candidates(
        self, origin_enu: np.ndarray, direction_enu: np.ndarray, dem, cutoff_m: float
    ) -> list[RoadCandidate]:
        """All crossings of a ray's ground track with the roads, out to ``cutoff_m``.

        Parameters
        ----------
        origin_enu, direction_enu : ndarray, shape (3,)
            Ray in the site frame; the direction need not be unit length.
        dem : Dem
            Provides the elevation at each crossing.
        cutoff_m : float
            Maximum distance along the ray (m).

        Returns
        -------
        list of RoadCandidate
            Sorted by range; crossings where the DEM has no data are left out.
        """
        o = np.asarray(origin_enu, dtype=np.float64)
        d = np.asarray(direction_enu, dtype=np.float64)
        d = d / np.linalg.norm(d)
        horiz = float(np.hypot(d[0], d[1]))
        if horiz < 1e-9:  # looking straight down: the ground track is a point
            return []
        end = o + d * cutoff_m
        track = LineString([o[:2], end[:2]])
        out: list[RoadCandidate] = []
        for idx in self._tree.query(track, predicate="intersects"):
            crossing = shapely.intersection(track, self.lines[int(idx)])
            pts = shapely.get_coordinates(crossing)
            for x, y in pts:
                rng = float(np.hypot(x - o[0], y - o[1])) / horiz
                z_ray = o[2] + rng * d[2]
                z_dem = float(dem.sample(np.array([x]), np.array([y]))[0])
                if not np.isfinite(z_dem):
                    continue
                out.append(
                    RoadCandidate(np.array([x, y, z_dem]), rng, abs(z_dem - z_ray), int(idx))
                )
        out.sort(key=lambda c: c.range_m)
        return out

    def best_candidate(
        self,
        origin_enu: np.ndarray,
        direction_enu: np.ndarray,
        dem,
        cutoff_m: float,
        max_gap_m: float = np.inf,
    ) -> RoadCandidate | None:
        """Apply the paper's road rule: return the crossing with the smallest vertical gap.

        A best crossing whose gap exceeds ``max_gap_m`` is no answer (the ray passes high
        above every road, so the target is not on one): None.
        """
        cands = self.ray_candidates(origin_enu, direction_enu, dem, cutoff_m)
        best = min(cands, key=lambda c: c.vertical_gap_m) if cands else None
        return best if best is not None and best.vertical_gap_m <= max_gap_m else None

    def best_candidates(
        self,
        origins_enu: np.ndarray,
        directions_enu: np.ndarray,
        dem,
        cutoff_m: float,
        max_gap_m: float = np.inf,
    ) -> RoadChoices:
        """The road rule for a batch of rays at once: :meth:`best_candidate` per ray.

        One bulk STRtree query and one vectorised intersection for all rays' ground
        tracks; the same choice as :meth:`best_candidate` (smallest vertical gap, the
        nearest of equal gaps).

        Parameters
        ----------
        origins_enu, directions_enu : ndarray, shape (n, 3)
            Rays in the site frame; directions need not be unit length.
        dem : Dem
            Provides the elevation at each crossing.
        cutoff_m : float
            Maximum distance along each ray (m).
        max_gap_m : float
            A best crossing with a larger vertical gap is no answer.

        Returns
        -------
        RoadChoices
        """
        o = np.asarray(origins_enu, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(directions_enu, dtype=np.float64).reshape(-1, 3)
        n = len(o)
        out = RoadChoices(np.full((n, 3), np.nan), np.full(n, np.nan), np.full(n, -1, np.int64))
        if n == 0 or not self.lines:
            return out
        d = d / np.linalg.norm(d, axis=1)[:, None]
        horiz = np.hypot(d[:, 0], d[:, 1])
        rays = np.flatnonzero(horiz >= 1e-9)  # straight down: the ground track is a point
        end = o[rays] + d[rays] * cutoff_m
        # Only the part of each ground track over the DEM can give a crossing (the
        # elevation is NaN elsewhere): clipped to it, a track meets fewer road segments.
        # The box is the DEM's surface padded by a cell, so a clipped end is off the
        # surface and no crossing on it is lost; ranges are still from the ray's origin.
        x0, y0, x1, y1 = dem.grid.centre_bounds
        pad = dem.grid.cell_m
        start, stop, over = _clip_to_box(
            o[rays, :2], end[:, :2], (x0 - pad, y0 - pad, x1 + pad, y1 + pad)
        )
        rays, start, stop = rays[over], start[over], stop[over]
        tracks = shapely.linestrings(np.stack([start, stop], axis=1))
        pair_track, pair_seg = self._segment_tree.query(tracks)  # bounding boxes only
        if len(pair_track) == 0:
            return out
        xy, which = self._crossings(start[pair_track], stop[pair_track], pair_seg)
        if len(which) == 0:
            return out
        ray = rays[pair_track[which]]
        road = self._segment_road[pair_seg[which]]
        x, y = xy[:, 0], xy[:, 1]
        rng = np.hypot(x - o[ray, 0], y - o[ray, 1]) / horiz[ray]
        z_ray = o[ray, 2] + rng * d[ray, 2]
        z_dem = dem.sample(x, y)
        ok = np.isfinite(z_dem)
        x, y, rng, z_dem, ray, road = x[ok], y[ok], rng[ok], z_dem[ok], ray[ok], road[ok]
        gap = np.abs(z_dem - z_ray[ok])
        # Per ray, the smallest gap first; among equal gaps the nearest (as the scalar rule
        # picks the first minimum of the range-sorted list).
        order = np.lexsort((rng, gap, ray))
        first = np.ones(len(order), bool)
        first[1:] = ray[order[1:]] != ray[order[:-1]]
        best = order[first]
        best = best[gap[best] <= max_gap_m]
        r = ray[best]
        out.p_enu[r] = np.column_stack([x[best], y[best], z_dem[best]])
        out.vertical_gap_m[r] = gap[best]
        out.road_index[r] = road[best]
        return out

    def _crossings(
        self, start: np.ndarray, stop: np.ndarray, seg: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Where each track ``start -> stop`` (k, 2) meets road segment ``seg`` (k,).

        Returns the crossing points (c, 2) and, for each, the index of its pair. Computed
        in closed form (the two segments' parameters from 2-D cross products) instead of
        GEOS's intersection of every candidate pair, which was most of the road rule's
        time; parallel pairs (which can only overlap) go to shapely, as before, and give
        the ends of their overlap.
        """
        a = self._segment_xy[seg, 0]
        q = self._segment_xy[seg, 1] - a
        r = stop - start
        ap = a - start
        denom = r[:, 0] * q[:, 1] - r[:, 1] * q[:, 0]
        parallel = denom == 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            s = (ap[:, 0] * q[:, 1] - ap[:, 1] * q[:, 0]) / denom
            u = (ap[:, 0] * r[:, 1] - ap[:, 1] * r[:, 0]) / denom
        crossing = ~parallel & (s >= 0.0) & (s <= 1.0) & (u >= 0.0) & (u <= 1.0)
        which = np.flatnonzero(crossing)
        xy = start[which] + s[which, None] * r[which]
        pairs = np.flatnonzero(parallel)
        if len(pairs):
            tracks = shapely.linestrings(np.stack([start[pairs], stop[pairs]], axis=1))
            overlap = shapely.intersection(tracks, self._segments[seg[pairs]])
            more, k = shapely.get_coordinates(overlap, return_index=True)
            xy = np.concatenate([xy, more])
            which = np.concatenate([which, pairs[k]])
        return xy, which

    def distance_m(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Horizontal distance (m) from each point to the nearest road centre line."""
        pts = shapely.points(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        if not self.lines:  # an empty tree's nearest() returns nothing, not one per point
            return np.full(np.shape(pts), np.inf)
        nearest = self._tree.nearest(pts)
        return shapely.distance(pts, np.asarray(self.lines, dtype=object)[nearest])
