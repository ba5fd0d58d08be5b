"""The true world of the sample site, defined analytically in the site frame.

A Bushy-Run-like layout of about 300 m x 300 m (Collins et al. 1998 used the Bushy Run
Battlefield, Pennsylvania): an asphalt road loop around an open field, an entrance road
from the west, a spur down the hill to a parking lot in the south-east, two large
flat-roofed buildings and stands of trees whose crowns overhang the road in places.

Everything here is ground truth: ``ground_z`` is the bare earth, ``surface_z`` what an
airborne laser's first return sees (ground, roofs and tree crowns). All heights are
local-frame Z (m); the frame is anchored at :data:`ANCHOR`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

__all__ = [
    "ANCHOR",
    "BUILDINGS",
    "EXTENT_M",
    "Building",
    "Tree",
    "World",
    "make_world",
]

#: WGS84 anchor of the site frame: Bushy Run Battlefield, PA (lat, lon, ellipsoidal h).
#: The ground there is about 365 m above the geoid; the EGM96 undulation is -33.97 m
#: (site.json states EGM96, so sea-level heights are h + 33.97 m near the anchor).
ANCHOR = (40.3556, -79.6225, 331.0)
#: Half-width of the square site (m): the site spans [-EXTENT_M, EXTENT_M] in x and y.
EXTENT_M = 150.0


@dataclass(frozen=True)
class Building:
    """A flat-roofed box: footprint ``[x0, x1] x [y0, y1]`` and roof height above ground."""

    name: str
    x0: float
    x1: float
    y0: float
    y1: float
    height_m: float


@dataclass(frozen=True)
class Tree:
    """A tree crown: a paraboloid cap of radius ``r_m``, ``base_m`` to ``top_m`` above ground."""

    x: float
    y: float
    r_m: float
    base_m: float
    top_m: float


BUILDINGS = (
    Building("visitor centre", 72.0, 112.0, -62.0, -40.0, 8.0),
    Building("museum", -52.0, -14.0, 104.0, 126.0, 9.0),
)

PARKING = (62.0, 128.0, -132.0, -78.0)  # x0, x1, y0, y1


def _smoothstep(e0: float, e1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _loop_polyline(n: int = 240) -> np.ndarray:
    """Return the road loop: a superellipse around the field, counter-clockwise, closed."""
    th = np.linspace(0, 2 * np.pi, n + 1)
    cx, cy, ax, ay, p = -8.0, 12.0, 92.0, 78.0, 3.0
    c, s = np.cos(th), np.sin(th)
    x = cx + ax * np.sign(c) * np.abs(c) ** (2 / p)
    y = cy + ay * np.sign(s) * np.abs(s) ** (2 / p)
    return np.column_stack([x, y])


def _entrance_polyline() -> np.ndarray:
    """From the west edge of the site to the loop's west side."""
    x = np.linspace(-EXTENT_M - 5, -99.0, 30)
    y = 5.0 + 4.0 * np.sin((x + EXTENT_M) / 25.0)
    return np.column_stack([x, y])


def _spur_polyline() -> np.ndarray:
    """From the loop's south-east corner down the hill into the parking lot."""
    pts = np.array(
        [
            [70.0, -55.0],
            [66.0, -70.0],
            [72.0, -86.0],
            [86.0, -96.0],
            [100.0, -100.0],
            [114.0, -104.0],
        ]
    )
    # Start on the loop itself so the network is connected at a junction.
    loop = _loop_polyline()
    pts = np.vstack([loop[np.argmin(np.hypot(*(loop - pts[0]).T))], pts])
    # Densify so the polyline follows the terrain closely.
    out = [pts[0]]
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        for t in np.linspace(0, 1, 8)[1:]:
            out.append(a + t * (b - a))
    return np.array(out)


def _trees(rng: np.random.Generator) -> tuple[Tree, ...]:
    trees = []
    # Stands along the loop's north-east and south sides and beside the spur, so crowns
    # overhang the road where the cameras look across them.
    stands = [
        ((40.0, 92.0), 30.0, 18),
        ((-70.0, -62.0), 28.0, 16),
        ((52.0, -78.0), 16.0, 9),
        ((-120.0, 60.0), 25.0, 12),
        ((125.0, 20.0), 20.0, 10),
    ]
    for (sx, sy), spread, n in stands:
        for _ in range(n):
            x, y = sx + rng.normal(0, spread / 2), sy + rng.normal(0, spread / 2)
            r = rng.uniform(3.0, 5.5)
            top = rng.uniform(12.0, 18.0)
            trees.append(Tree(float(x), float(y), float(r), float(top * 0.35), float(top)))
    return tuple(trees)


@dataclass(frozen=True, eq=False)
class World:
    """The sample site's ground truth."""

    roads: dict[str, np.ndarray]
    road_width_m: float
    buildings: tuple[Building, ...]
    trees: tuple[Tree, ...]

    def ground_z(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Bare-earth elevation (m): a hill falling from the north-west down to the parking lot."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        z = 12.0 + 10.0 * np.tanh((y - x) / 120.0)
        z += 0.5 * np.sin(x / 29.0) * np.cos(y / 37.0) + 0.1 * np.sin((x + 2 * y) / 13.0)
        px0, px1, py0, py1 = PARKING
        ramp = 18.0  # the lot is cut into the slope; its banks are this wide (m)
        inside = (
            _smoothstep(px0 - ramp, px0, x)
            * (1 - _smoothstep(px1, px1 + ramp, x))
            * _smoothstep(py0 - ramp, py0, y)
            * (1 - _smoothstep(py1, py1 + ramp, y))
        )
        lot_level = 12.0 + 10.0 * np.tanh(((py0 + py1) / 2 - (px0 + px1) / 2) / 120.0) - 3.0
        return z * (1 - inside) + lot_level * inside

    def building_z(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Roof elevation where a building stands, NaN elsewhere."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        out = np.full(np.broadcast(x, y).shape, np.nan)
        for b in self.buildings:
            inside = (x >= b.x0) & (x <= b.x1) & (y >= b.y0) & (y <= b.y1)
            # A flat roof: the ground at the building's centre plus its height.
            roof = float(self.ground_z((b.x0 + b.x1) / 2, (b.y0 + b.y1) / 2)) + b.height_m
            out = np.where(inside, roof, out)
        return out

    def crown_z(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Top of the tree crowns (m), NaN where no crown is overhead."""
        x, y = np.broadcast_arrays(np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
        shape = x.shape
        x, y = x.ravel(), y.ravel()
        out = np.full(x.shape, np.nan)
        g = self.ground_z(x, y)
        # Each tree is evaluated on the points near it only (a crown covers a tiny share
        # of the site): the same arithmetic on every point it can reach, so the same bits
        # as evaluating it everywhere. Sorting by x once makes "near" two binary searches.
        order = np.argsort(x, kind="stable")
        xs = x[order]
        for t in self.trees:
            reach = t.r_m * 1.001 + 1e-9  # wider than the disc: rounding cannot drop a point
            lo = int(np.searchsorted(xs, t.x - reach, side="left"))
            hi = int(np.searchsorted(xs, t.x + reach, side="right"))
            idx = order[lo:hi]
            idx = idx[np.abs(y[idx] - t.y) <= reach]
            xi, yi = x[idx], y[idx]
            r2 = ((xi - t.x) ** 2 + (yi - t.y) ** 2) / t.r_m**2
            top = float(self.ground_z(t.x, t.y)) + t.top_m
            base = float(self.ground_z(t.x, t.y)) + t.base_m
            z = top - (top - base) * r2
            z = np.where((r2 <= 1.0) & (z > g[idx]), z, np.nan)
            out[idx] = np.fmax(out[idx], z)
        return out.reshape(shape)

    def surface_z(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """First-return surface (m): the highest of ground, roof and crown."""
        return np.fmax(np.fmax(self.ground_z(x, y), self.building_z(x, y)), self.crown_z(x, y))

    def road_distance(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Horizontal distance to the nearest road centre line (m)."""
        import shapely

        pts = shapely.points(
            np.asarray(x, dtype=np.float64).ravel(), np.asarray(y, dtype=np.float64).ravel()
        )
        lines = shapely.multilinestrings([shapely.linestrings(p) for p in self.roads.values()])
        return shapely.distance(pts, lines).reshape(np.shape(x))

    def in_parking(self, x: ArrayLike, y: ArrayLike) -> np.ndarray:
        """Tell whether each point lies on the parking lot's paved area."""
        px0, px1, py0, py1 = PARKING
        xa = np.asarray(x, dtype=np.float64)
        ya = np.asarray(y, dtype=np.float64)
        return (xa >= px0) & (xa <= px1) & (ya >= py0) & (ya <= py1)


def make_world(seed: int = 7) -> World:
    """Build the deterministic sample world."""
    rng = np.random.default_rng(seed)
    roads = {
        "loop": _loop_polyline(),
        "entrance": _entrance_polyline(),
        "parking spur": _spur_polyline(),
    }
    world = World(roads, 6.0, BUILDINGS, ())
    trees = tuple(
        t
        for t in _trees(rng)
        if not any(
            b.x0 - t.r_m < t.x < b.x1 + t.r_m and b.y0 - t.r_m < t.y < b.y1 + t.r_m
            for b in BUILDINGS
        )
        and not world.in_parking(np.array(t.x), np.array(t.y))
    )
    return World(roads, 6.0, BUILDINGS, trees)
