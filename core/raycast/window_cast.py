"""An in-memory cast over a window of a tiled DEM, in the whole DEM's frame: the same bits.

A window read into a plain :class:`~demtrack.core.terrain.dem.Dem` (``TiledDem.window_dem``)
has its own grid origin, height range and min/max pyramid, so ``RayCaster`` over it rounds
differently from a cast over the whole DEM (hit points differ by up to 1e-9 m): the ray's
grid coordinates are ``(ox - x_min) / cell - 0.5`` from another ``x_min``, the hull and
height-slab clips give another walked stretch, hence another start level, and the walk adds
node widths to face ranges along another chain of nodes (coarse nodes of a window cover
only the window).

:class:`WindowRayCaster` is the in-memory ``RayCaster``, kernels unchanged, over arrays in
the *whole* DEM's frame of which only the window is filled: the elevation grid and the
pyramid's node table have the whole DEM's shapes and live in one lazily committed anonymous
mapping each (pages never written cost no memory), the window's cells (whole patch blocks,
so its pyramid levels below the block level are the whole DEM's) are copied in, and the
levels at and above the block level come from the file's block min/max, as the tiled
caster keeps them. The grid's origin, shape and height range are the whole DEM's. Every ray
then runs the very operations of ``RayCaster`` over the whole DEM, which is what
``TiledRayCaster`` gives too; rays must stay inside the window (checked), and the angular
index is not used (``coherent=False`` always: it would read past the window).
"""

from __future__ import annotations

import mmap
from dataclasses import dataclass
from typing import Literal

import numpy as np

from ..errors import RaycastError
from ..terrain.tiled_dem import TiledDem
from .cast import RayCaster, RayHits
from .pyramid import MinMaxPyramid, build_pyramid, pyramid_level_shapes, pyramid_levels_above

__all__ = ["WindowRayCaster", "lazy_zeros"]


def lazy_zeros(shape: tuple[int, ...], dtype: type) -> np.ndarray:
    """A zero array in its own anonymous mapping: only the pages written take memory."""
    n = max(int(np.prod(shape)) * np.dtype(dtype).itemsize, 1)
    flags = mmap.MAP_PRIVATE | getattr(mmap, "MAP_ANONYMOUS", 0x20)
    flags |= getattr(mmap, "MAP_NORESERVE", 0)
    buf = mmap.mmap(-1, n, flags=flags)
    return np.frombuffer(buf, dtype=dtype, count=int(np.prod(shape))).reshape(shape)


@dataclass(frozen=True, eq=False)
class WindowRayCaster(RayCaster):
    """``RayCaster`` over a window ``(by0, by1, bx0, bx1)`` of a tiled DEM's patch blocks.

    Build with :meth:`for_rays` (the blocks the rays reach) or :meth:`from_blocks`.
    ``window`` is the window in cell rows and columns ``(r0, r1, c0, c1)`` (ends
    exclusive): the blocks' cells, with the next row and column their patches reach.
    """

    window: tuple[int, int, int, int] = (0, 0, 0, 0)

    @classmethod
    def from_blocks(cls, td: TiledDem, by0: int, by1: int, bx0: int, bx1: int) -> WindowRayCaster:
        """The caster of patch blocks ``by0 .. by1 - 1`` x ``bx0 .. bx1 - 1`` of ``td``."""
        g, t = td.grid, td.tile
        nby, nbx = td.minmax.shape[:2]
        if not (0 <= by0 < by1 <= nby and 0 <= bx0 < bx1 <= nbx):
            raise RaycastError(f"blocks {by0}:{by1}, {bx0}:{bx1} outside {nby} x {nbx}")
        r0, c0 = by0 * t, bx0 * t
        r1, c1 = min(by1 * t + 1, g.nrows), min(bx1 * t + 1, g.ncols)
        shapes = pyramid_level_shapes(g.nrows, g.ncols)
        sizes = shapes[:, 0] * shapes[:, 1]
        offsets = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        elev = lazy_zeros(g.shape, np.float32)
        nodes = lazy_zeros((int(sizes.sum()), 2), np.float32)
        cells = td.read_cells(r0, r1, c0, c1)
        elev[r0:r1, c0:c1] = cells
        t_level = t.bit_length() - 1
        top = len(shapes)
        # Below the block level: the window's own pyramid, whose nodes are the whole DEM's
        # (the window starts on a block corner and holds whole blocks).
        fine = build_pyramid(cells) if min(t_level - 1, top) >= 1 else None
        for k in range(1, min(t_level - 1, top) + 1):
            lv = fine.level(k)  # type: ignore[union-attr]
            rows, cols = (int(v) for v in shapes[k - 1])
            dst = nodes[offsets[k - 1] : offsets[k - 1] + rows * cols].reshape(rows, cols, 2)
            dst[r0 >> k : (r0 >> k) + lv.shape[0], c0 >> k : (c0 >> k) + lv.shape[1]] = lv
        # At and above it: the file's block min/max and its coarser levels, as the tiled
        # caster holds them.
        if t_level <= top:
            for k, lv in enumerate(pyramid_levels_above(td.minmax), start=t_level):
                rows, cols = (int(v) for v in shapes[k - 1])
                nodes[offsets[k - 1] : offsets[k - 1] + rows * cols] = lv.reshape(-1, 2)
        elev.setflags(write=False)
        nodes.setflags(write=False)
        pyramid = MinMaxPyramid(nodes, offsets, shapes, td.z_min, td.z_max)
        return cls(g, elev, pyramid, window=(r0, r1, c0, c1))

    @classmethod
    def for_rays(
        cls,
        td: TiledDem,
        origins: np.ndarray,
        directions: np.ndarray,
        max_range: float,
    ) -> WindowRayCaster:
        """The caster of the blocks the rays reach within ``max_range`` (finite, m) + one cell."""
        lo, hi = _footprint_box(td, origins, directions, max_range)
        t = td.tile
        nby, nbx = td.minmax.shape[:2]
        b_lo = np.clip(np.floor(lo - 1.0) // t, 0, [nby - 1, nbx - 1]).astype(int)
        b_hi = np.clip(np.floor(hi + 1.0) // t, 0, [nby - 1, nbx - 1]).astype(int)
        return cls.from_blocks(td, int(b_lo[0]), int(b_hi[0]) + 1, int(b_lo[1]), int(b_hi[1]) + 1)

    def cast(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        max_range: float | np.ndarray = np.inf,
        *,
        mode: Literal["all", "first"] = "all",
        max_hits: int = 256,
        coherent: bool | None = None,
    ) -> RayHits:
        """``RayCaster.cast`` with the pyramid walk (``coherent`` is ignored).

        Raises
        ------
        RaycastError
            If a ray's footprint within ``max_range`` leaves the window (a cast there
            would read cells that are not loaded).
        """
        box = _footprint_box(self, origins, directions, max_range)
        g = self.grid
        r0, r1, c0, c1 = self.window
        # One cell inside the window's edges, except where they are the DEM's own.
        y_lo, x_lo = (r0 + 1.0 if r0 > 0 else -np.inf), (c0 + 1.0 if c0 > 0 else -np.inf)
        y_hi = r1 - 2.0 if r1 < g.nrows else np.inf
        x_hi = c1 - 2.0 if c1 < g.ncols else np.inf
        if box[0][0] < y_lo or box[0][1] < x_lo or box[1][0] > y_hi or box[1][1] > x_hi:
            raise RaycastError(f"rays reach past the window rows {r0}:{r1}, cols {c0}:{c1}")
        return super().cast(
            origins, directions, max_range, mode=mode, max_hits=max_hits, coherent=False
        )


def _footprint_box(
    dem: TiledDem | RayCaster,
    origins: np.ndarray,
    directions: np.ndarray,
    max_range: float | np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Grid ``(row, col)`` corners (low, high) of the box around the rays' footprints."""
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    rng = np.broadcast_to(np.asarray(max_range, np.float64), (len(o),))
    if not np.all(np.isfinite(rng)):
        raise RaycastError("a windowed cast needs a finite max_range")
    g = dem.grid
    ends = o[:, :2] + rng[:, None] * u[:, :2]
    gx, gy = g.to_grid(np.r_[o[:, 0], ends[:, 0]], np.r_[o[:, 1], ends[:, 1]])
    return np.array([gy.min(), gx.min()]), np.array([gy.max(), gx.max()])
