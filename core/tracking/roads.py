"""Road network and a road-constrained particle motion model (vehicles, optional).

Roads are shapely LineStrings in the local frame (x east, y north, m). They are noded
(split where they cross) and their end points merged into junctions, giving a graph of
edges. A road particle is ``(edge, s, v, lateral)``: arc length ``s`` along the edge
(m), signed speed ``v`` along it (m/s), and a lateral offset from the centreline (m, left
positive) so lanes and road width are represented. Particles run along edges and, at a
junction, continue onto a random other edge (dead ends turn back), so they can only be
where a vehicle on the network can be. Off-network vehicles are not this model's job.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

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


@dataclass(frozen=True, eq=False)
class RoadParticles:
    """Particles on a road network (arrays of shape (n,), plus ``xy`` (n, 2))."""

    edge: np.ndarray
    s: np.ndarray
    v: np.ndarray
    lateral: np.ndarray
    xy: np.ndarray


@dataclass(frozen=True)
class RoadParticleMotion:
    """Road-constrained constant-speed motion for a particle filter.

    Parameters
    ----------
    network : RoadGraph
        The roads.
    q_m2_s3 : float
        Along-road acceleration noise spectral density (m^2/s^3).
    init_speed_sigma_m_s : float
        1-sigma of the initial along-road speed (m/s).
    max_lateral_m : float
        Lateral offsets are clipped to this (half the road width, m).
    lateral_walk_m_sqrt_s : float
        Random-walk rate of the lateral offset (lane changes), m/sqrt(s).
    """

    network: RoadGraph
    q_m2_s3: float
    init_speed_sigma_m_s: float
    max_lateral_m: float = 4.0
    lateral_walk_m_sqrt_s: float = 0.3

    def _build(
        self, edge: np.ndarray, s: np.ndarray, v: np.ndarray, lateral: np.ndarray
    ) -> RoadParticles:
        centre, normal = self.network.frame(edge, s)
        return RoadParticles(edge, s, v, lateral, centre + lateral[:, None] * normal)

    def initial(self, cands: Candidates, n: int, rng: np.random.Generator) -> RoadParticles:
        """Draw samples around the candidates, snapped onto the nearest roads."""
        xy = sample_candidates(cands, n, rng)
        edge, s, lateral = self.network.snap(xy)
        lateral = np.clip(lateral, -self.max_lateral_m, self.max_lateral_m)
        v = self.init_speed_sigma_m_s * rng.standard_normal(n)
        return self._build(edge, s, v, lateral)

    def propagate(
        self, particles: RoadParticles, dt_s: float, rng: np.random.Generator
    ) -> RoadParticles:
        """Along-road constant velocity with exact discrete noise, across junctions."""
        if dt_s <= 0.0:
            return particles
        n = particles.s.shape[0]
        axis = self.q_m2_s3 * np.array([[dt_s**3 / 3.0, dt_s**2 / 2.0], [dt_s**2 / 2.0, dt_s]])
        noise = rng.standard_normal((n, 2)) @ np.linalg.cholesky(axis).T
        s = particles.s + dt_s * particles.v + noise[:, 0]
        v = particles.v + noise[:, 1]
        lateral = particles.lateral + self.lateral_walk_m_sqrt_s * np.sqrt(
            dt_s
        ) * rng.standard_normal(n)
        edge, s, v, lateral = self.network.advance(particles.edge, s, v, lateral, rng)
        lateral = np.clip(lateral, -self.max_lateral_m, self.max_lateral_m)
        return self._build(edge, s, v, lateral)

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
        )
