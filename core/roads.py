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

from .errors import InputFileError

__all__ = ["RoadCandidate", "RoadNetwork"]


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

    def distance_m(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Horizontal distance (m) from each point to the nearest road centre line."""
        pts = shapely.points(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        if not self.lines:  # an empty tree's nearest() returns nothing, not one per point
            return np.full(np.shape(pts), np.inf)
        nearest = self._tree.nearest(pts)
        return shapely.distance(pts, np.asarray(self.lines, dtype=object)[nearest])
