"""Road network and a road-constrained particle motion model (vehicles, optional).

Roads are shapely LineStrings in the local frame (x east, y north, m). They are noded
(split where they cross) and their end points merged into junctions, giving a graph of
edges. A road particle is ``(edge, s, v, lateral)``: arc length ``s`` along the edge
(m), signed speed ``v`` along it (m/s), and a lateral offset from the centreline (m, left
positive) so lanes and road width are represented. Particles run along edges and, at a
junction, continue onto a random other edge (dead ends turn back), so they can only be
where a vehicle on the network can be - unless they take the model's off-road mode
(car parks, yards), a constant-velocity walk in the plane entered and left at set rates.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import cast

import numpy as np
import shapely
from shapely import LineString, MultiLineString, STRtree

from ..errors import TrackingError
from .motion import sample_candidates
from .protocols import Candidates

__all__ = ["RoadGraph", "RoadParticles", "RoadParticleMotion"]


class RoadGraph:
    """A noded graph of road centrelines.

    Parameters
    ----------
    lines : sequence of shapely.LineString
        Centrelines in the local frame (m); z, if any, is ignored.
    junction_tolerance_m : float
        End points closer than this are one junction (m).
    """

    def __init__(self, lines: Sequence[LineString], junction_tolerance_m: float = 0.5) -> None:
        lines = [shapely.force_2d(line) for line in lines]
        #: The centrelines as given (2-D), before noding.
        self.lines: tuple[LineString, ...] = tuple(lines)
        if not lines or any(
            not isinstance(g, LineString) or g.is_empty or g.length <= 0 for g in lines
        ):
            raise TrackingError("a road network needs at least one non-empty LineString")
        noded = shapely.node(MultiLineString(lines))
        self.edges: np.ndarray = np.array(list(noded.geoms), dtype=object)
        self.length_m: np.ndarray = shapely.length(self.edges).astype(np.float64)
        ends = np.array([[e.coords[0][:2], e.coords[-1][:2]] for e in self.edges])  # (E, 2, 2)
        nodes: list[np.ndarray] = []
        node_of = np.empty((len(self.edges), 2), dtype=np.int64)
        for i in range(len(self.edges)):
            for k in (0, 1):
                p = ends[i, k]
                for n_id, q in enumerate(nodes):
                    if np.hypot(*(p - q)) <= junction_tolerance_m:
                        node_of[i, k] = n_id
                        break
                else:
                    nodes.append(p)
                    node_of[i, k] = len(nodes) - 1
        #: ``node_of[e] = (start junction, end junction)``.
        self.node_of = node_of
        #: Per junction, the (edge, end) pairs meeting there; end 0 = start, 1 = end.
        self.incident: list[list[tuple[int, int]]] = [[] for _ in nodes]
        for i in range(len(self.edges)):
            for k in (0, 1):
                self.incident[node_of[i, k]].append((i, k))
        self._tree = STRtree(list(self.edges))
        # All edges' vertices end to end, with arc lengths on one global axis, so the
        # position at (edge, s) of many particles is one searchsorted (no shapely calls).
        verts: list[np.ndarray] = []
        cum: list[np.ndarray] = []
        first: list[int] = []
        base = 0.0
        for e in self.edges:
            v = np.asarray(e.coords, dtype=np.float64)[:, :2]
            keep = np.append(True, np.any(np.diff(v, axis=0) != 0, axis=1))
            v = v[keep]
            first.append(sum(len(x) for x in verts))
            verts.append(v)
            cum.append(base + np.append(0.0, np.cumsum(np.linalg.norm(np.diff(v, axis=0), axis=1))))
            base = cum[-1][-1]
        self._verts = np.concatenate(verts)
        self._cum = np.concatenate(cum)
        self._first = np.array(first, dtype=np.int64)
        self._nverts = np.array([len(v) for v in verts], dtype=np.int64)
        self._base = np.array([c[0] for c in cum])

    def snap(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Nearest edge, arc length and signed lateral offset of points ``xy`` (n, 2)."""
        pts = shapely.points(np.asarray(xy, dtype=np.float64))
        edge = self._tree.query_nearest(pts, all_matches=False)[1]
        s = shapely.line_locate_point(self.edges[edge], pts).astype(np.float64)
        centre, normal = self.frame(edge, s)
        lateral = np.sum((xy - centre) * normal, axis=1)
        return edge.astype(np.int64), s, lateral

    def frame(self, edge: np.ndarray, s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Centreline points (n, 2) and unit left normals (n, 2) at ``(edge, s)``.

        ``s`` is clipped to the edge; the normal is that of the segment holding the point.
        """
        edge = np.asarray(edge, dtype=np.int64)
        g = self._base[edge] + np.clip(s, 0.0, self.length_m[edge])
        lo = self._first[edge]
        hi = lo + self._nverts[edge] - 2  # last segment of the edge
        seg = np.clip(np.searchsorted(self._cum, g, side="right") - 1, lo, hi)
        a, b = self._verts[seg], self._verts[seg + 1]
        span = self._cum[seg + 1] - self._cum[seg]
        frac = ((g - self._cum[seg]) / span)[:, None]
        tangent = (b - a) / span[:, None]
        return a + frac * (b - a), np.stack([-tangent[:, 1], tangent[:, 0]], axis=1)

    def advance(
        self,
        edge: np.ndarray,
        s: np.ndarray,
        v: np.ndarray,
        lateral: np.ndarray,
        rng: np.random.Generator,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Carry positions past junctions: ``s`` may lie outside ``[0, length]`` on entry.

        Returns new ``(edge, s, v, lateral)`` with every ``s`` on its edge. At a junction a
        particle continues onto a random other edge, keeping its speed magnitude, heading
        away from the junction, and its side of the road relative to its travel; at a dead
        end it turns back.
        """
        edge, s, v, lateral = edge.copy(), s.copy(), v.copy(), lateral.copy()
        for _ in range(100):  # more junctions per step than this is a degenerate network
            over = s > self.length_m[edge]
            under = s < 0.0
            todo = np.flatnonzero(over | under)
            if todo.size == 0:
                return edge, s, v, lateral
            for i in todo:
                e = int(edge[i])
                k = 1 if over[i] else 0
                spill = s[i] - self.length_m[e] if k == 1 else -s[i]
                node = int(self.node_of[e, k])
                options = [o for o in self.incident[node] if o != (e, k)]
                if not options:
                    options = [(e, k)]  # dead end: back the way it came
                ne, nk = options[int(rng.integers(len(options)))]
                speed = abs(v[i])
                if nk == k:  # the new edge runs the other way: left and right swap
                    lateral[i] = -lateral[i]
                edge[i] = ne
                if nk == 0:  # entering at the start: run forward
                    s[i], v[i] = spill, speed
                else:
                    s[i], v[i] = self.length_m[ne] - spill, -speed
        raise TrackingError("road particles crossed too many junctions in one step")


# Default of the optional ``RoadParticles`` arrays: omitted at construction,
# ``__post_init__`` replaces it, so on built particles the attribute is always an ndarray.
_FILLED_BY_POST_INIT = cast("np.ndarray", None)


@dataclass(frozen=True, eq=False)
class RoadParticles:
    """Particles on (or off) a road network.

    Arrays of shape (n,): ``edge``, ``s`` (m), ``v`` (m/s), ``lateral`` (m) describe a
    particle on the roads; ``free`` marks those off them (car parks, yards, dead ends),
    which move by constant velocity ``vxy`` (n, 2) (m/s) in the plane instead and whose
    road fields are stale. ``xy`` (n, 2) is every particle's position (m).
    """

    edge: np.ndarray
    s: np.ndarray
    v: np.ndarray
    lateral: np.ndarray
    xy: np.ndarray
    free: np.ndarray = _FILLED_BY_POST_INIT
    vxy: np.ndarray = _FILLED_BY_POST_INIT

    def __post_init__(self) -> None:
        n = self.s.shape[0]
        if self.free is None:
            object.__setattr__(self, "free", np.zeros(n, dtype=bool))
        if self.vxy is None:
            object.__setattr__(self, "vxy", np.zeros((n, 2)))


def _cv_noise(q: float, dt_s: float, shape: tuple[int, ...], rng: np.random.Generator):
    """Exact discrete white-acceleration noise: (position, velocity) draws of ``shape``."""
    axis = q * np.array([[dt_s**3 / 3.0, dt_s**2 / 2.0], [dt_s**2 / 2.0, dt_s]])
    noise = rng.standard_normal((*shape, 2)) @ np.linalg.cholesky(axis).T
    return noise[..., 0], noise[..., 1]


@dataclass(frozen=True)
class RoadParticleMotion:
    """Road-constrained constant-speed motion with an off-road mode, for a particle filter.

    On the roads a particle runs along an edge (constant speed, white along-road
    acceleration) with a slowly wandering lateral offset. Vehicles also leave the roads
    (into a car park, a yard, past a dead end), so the motion is a two-mode mixture: an
    on-road particle goes off-road at rate ``leave_rate_per_s`` (keeping its velocity),
    an off-road particle moves by constant velocity in the plane and rejoins the road at
    rate ``join_rate_per_s`` while it is within ``max_lateral_m`` of one. A new particle
    farther than ``max_lateral_m`` from every road starts off-road, as does a fraction
    ``p_free_init`` of the rest. The measurement weights then keep whichever mode
    explains the fixes. ``leave_rate_per_s = 0`` and ``p_free_init = 0`` give the strict
    on-road model (particles far from roads are then snapped onto them).

    Parameters
    ----------
    network : RoadGraph
        The roads.
    q_m2_s3 : float
        Acceleration noise spectral density (m^2/s^3), along the road and per axis off it.
    init_speed_sigma_m_s : float
        1-sigma of the initial speed (m/s) (along the road, or per axis off it).
    max_lateral_m : float
        Lateral offsets on a road are clipped to this (half the road width, m).
    lateral_walk_m_sqrt_s : float
        Random-walk rate of the lateral offset (lane changes), m/sqrt(s).
    leave_rate_per_s : float
        Rate at which an on-road particle leaves the road (1/s).
    join_rate_per_s : float
        Rate at which an off-road particle near a road joins it (1/s).
    p_free_init : float
        Share of new particles near a road that start off-road.
    """

    network: RoadGraph
    q_m2_s3: float
    init_speed_sigma_m_s: float
    max_lateral_m: float = 4.0
    lateral_walk_m_sqrt_s: float = 0.3
    leave_rate_per_s: float = 0.0
    join_rate_per_s: float = 1.0
    p_free_init: float = 0.0

    def __post_init__(self) -> None:
        rates_ok = self.leave_rate_per_s >= 0 and self.join_rate_per_s >= 0
        if not (rates_ok and 0.0 <= self.p_free_init <= 1.0 and self.max_lateral_m > 0):
            raise TrackingError(
                "road motion needs rates >= 0, p_free_init in [0, 1] and max_lateral_m > 0"
            )

    def _build(
        self,
        edge: np.ndarray,
        s: np.ndarray,
        v: np.ndarray,
        lateral: np.ndarray,
        free: np.ndarray,
        vxy: np.ndarray,
        free_xy: np.ndarray,
    ) -> RoadParticles:
        centre, normal = self.network.frame(edge, s)
        xy = centre + lateral[:, None] * normal
        xy[free] = free_xy[free]
        return RoadParticles(edge, s, v, lateral, xy, free, vxy)

    def initial(self, cands: Candidates, n: int, rng: np.random.Generator) -> RoadParticles:
        """Draw samples around the candidates; those near a road start on it."""
        xy = sample_candidates(cands, n, rng)
        edge, s, lateral = self.network.snap(xy)
        free = (np.abs(lateral) > self.max_lateral_m) | (rng.random(n) < self.p_free_init)
        if self.leave_rate_per_s == 0 and self.p_free_init == 0:
            free[:] = False  # the strict on-road model
        lateral = np.clip(lateral, -self.max_lateral_m, self.max_lateral_m)
        v = self.init_speed_sigma_m_s * rng.standard_normal(n)
        vxy = self.init_speed_sigma_m_s * rng.standard_normal((n, 2))
        return self._build(edge, s, v, lateral, free, vxy, xy)

    def propagate(
        self, particles: RoadParticles, dt_s: float, rng: np.random.Generator
    ) -> RoadParticles:
        """Move on or off the roads with exact discrete noise, then switch modes."""
        if dt_s <= 0.0:
            return particles
        n = particles.s.shape[0]
        free = particles.free.copy()
        # On the roads: along-road constant velocity, across junctions.
        ds, dv = _cv_noise(self.q_m2_s3, dt_s, (n,), rng)
        s = particles.s + dt_s * particles.v + ds
        v = particles.v + dv
        walk = self.lateral_walk_m_sqrt_s * np.sqrt(dt_s) * rng.standard_normal(n)
        lateral = particles.lateral + walk
        edge = particles.edge.copy()
        on = ~free
        if on.any():
            e, s_on, v_on, lat_on = self.network.advance(edge[on], s[on], v[on], lateral[on], rng)
            edge[on], s[on], v[on], lateral[on] = e, s_on, v_on, lat_on
        lateral = np.clip(lateral, -self.max_lateral_m, self.max_lateral_m)
        # Off the roads: constant velocity in the plane.
        dp, dvxy = _cv_noise(self.q_m2_s3, dt_s, (n, 2), rng)
        free_xy = particles.xy + dt_s * particles.vxy + dp
        vxy = particles.vxy + dvxy
        out = self._build(edge, s, v, lateral, free, vxy, free_xy)
        return self._switch(out, dt_s, rng)

    def _switch(self, p: RoadParticles, dt_s: float, rng: np.random.Generator) -> RoadParticles:
        """Leave or join the roads at the configured rates."""
        free = p.free.copy()
        vxy = p.vxy.copy()
        edge, s, v, lateral = p.edge.copy(), p.s.copy(), p.v.copy(), p.lateral.copy()
        xy = p.xy.copy()
        n = free.shape[0]
        u = rng.random(n)
        leave = ~free & (u < -np.expm1(-self.leave_rate_per_s * dt_s))
        if leave.any():
            _, normal = self.network.frame(edge[leave], s[leave])
            tangent = np.stack([normal[:, 1], -normal[:, 0]], axis=1)
            vxy[leave] = v[leave, None] * tangent
            free[leave] = True
        join = free & ~leave & (u < -np.expm1(-self.join_rate_per_s * dt_s))
        if join.any():
            e, sj, lat = self.network.snap(xy[join])
            near = np.abs(lat) <= self.max_lateral_m
            idx = np.flatnonzero(join)[near]
            if idx.size:
                e, sj, lat = e[near], sj[near], lat[near]
                _, normal = self.network.frame(e, sj)
                tangent = np.stack([normal[:, 1], -normal[:, 0]], axis=1)
                edge[idx], s[idx], lateral[idx] = e, sj, lat
                v[idx] = np.sum(vxy[idx] * tangent, axis=1)
                free[idx] = False
                # position unchanged: it was already within the road's width
        return RoadParticles(edge, s, v, lateral, xy, free, vxy)

    def positions(self, particles: RoadParticles) -> np.ndarray:
        """Horizontal positions, shape (n, 2)."""
        return particles.xy

    def take(self, particles: RoadParticles, index: np.ndarray) -> RoadParticles:
        """Return the particles at ``index``."""
        return RoadParticles(
            particles.edge[index],
            particles.s[index],
            particles.v[index],
            particles.lateral[index],
            particles.xy[index],
            particles.free[index],
            particles.vxy[index],
        )
