"""Ray casting over a tiled DEM larger than memory: the in-memory caster's answers, tile by tile.

:class:`TiledRayCaster` has :class:`~demtrack.core.raycast.cast.RayCaster`'s call surface
(:meth:`TiledRayCaster.cast`: origins and directions in, every crossing nearest first out,
as :class:`~demtrack.core.raycast.hits.RayHits`) over a
:class:`~demtrack.core.terrain.tiled_dem.TiledDem`. It keeps in memory only the coarse
levels of the min/max pyramid (one node per block of ``tile x tile`` patches, from the
file's metadata) and a :class:`~demtrack.core.raycast.tile_cache.TileCache` of decoded
blocks under ``memory_budget`` bytes.

The cast runs in rounds. The kernel (``core.raycast._tiled_walk_kernels``) walks every ray
until it ends or enters a block that is not resident, where it waits; the blocks most rays
wait for are then loaded (evicting the least recently used) and the waiting rays resume
where they stopped. A block the ray passes above is skipped on its coarse max without
being read. Since the walk is the in-memory caster's pyramid walk operation for operation
(same set-up, same node visits, same patch solver), the answers equal ``RayCaster``'s
pyramid walk (``coherent=False``) bit for bit, seams and corners included; with the angular
index (``coherent=True``, or ``None`` on long runs of one origin) the in-memory caster
agrees to rounding (well under 1e-9 m), as it says itself.
"""

from __future__ import annotations

import threading
from typing import Literal

import numpy as np

from ..errors import RaycastError
from ..terrain.tiled_dem import TiledDem
from . import _hit_kernels as _hk
from . import _tiled_walk_kernels as _tk
from .cast import HEIGHT_MARGIN_M, _threads_for, _validate_rays
from .hits import RayHits
from .pyramid import pyramid_level_shapes, pyramid_levels_above
from .tile_cache import CacheStats, TileCache

__all__ = ["DEFAULT_MEMORY_BUDGET", "FIRST_PASS_HITS", "TiledRayCaster"]

#: Budget of decoded blocks (bytes) where a caller names none (a site's geolocator).
DEFAULT_MEMORY_BUDGET = 1 << 30
_CAST_LOCK = threading.Lock()
#: Hits kept per ray in the first pass of ``mode="all"``; rays with more are cast again
#: with room for ``max_hits`` (as the in-memory caster re-walks them).
FIRST_PASS_HITS = 8


class TiledRayCaster:
    """Ray casting against a :class:`TiledDem`, loading only the blocks rays visit.

    Parameters
    ----------
    dem : TiledDem
        The tiled DEM (``core.terrain.tiled_dem``).
    memory_budget : int
        Bytes the decoded blocks may hold (the cache's pool; at least one block). The
        coarse levels, the rays' state and GDAL's small block cache are extra.

    Attributes
    ----------
    grid : GridSpec
        The DEM's grid.
    cache : TileCache
        The decoded blocks; ``cache.stats`` counts loads, evictions, hits and misses.
    """

    def __init__(self, dem: TiledDem, memory_budget: int) -> None:
        self.dem = dem
        self.grid = dem.grid
        self.cache = TileCache(dem, memory_budget)
        nrows, ncols = dem.grid.shape
        self.lvl_shape = pyramid_level_shapes(nrows, ncols)
        top = len(self.lvl_shape)
        t_level = self.cache.tile_level
        coarse: list[np.ndarray] = []
        if t_level <= top:
            coarse = pyramid_levels_above(dem.minmax)
            shapes = np.asarray([lv.shape[:2] for lv in coarse], np.int64)
            if not np.array_equal(shapes, self.lvl_shape[t_level - 1 :]):
                raise RaycastError(f"{dem.path}: block min/max does not fit the grid's pyramid")
        sizes = [lv.shape[0] * lv.shape[1] for lv in coarse]
        self.coarse_off = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)[
            : len(coarse)
        ]
        self.coarse = (
            np.ascontiguousarray(np.concatenate([lv.reshape(-1, 2) for lv in coarse]), np.float32)
            if coarse
            else np.zeros((0, 2), np.float32)
        )
        self.block_max = np.ascontiguousarray(dem.minmax[..., 0], np.float32)
        self._round = 0

    @classmethod
    def open(cls, path: str, memory_budget: int) -> TiledRayCaster:
        """:class:`TiledDem.open` then a caster over it."""
        return cls(TiledDem.open(path), memory_budget)

    @property
    def stats(self) -> CacheStats:
        """The cache's counters."""
        return self.cache.stats

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
        """Cast rays; the arguments and answer of :func:`~demtrack.core.raycast.cast.cast_rays`.

        ``coherent`` is accepted for the same call surface and ignored (the tiled walk
        has no angular index; the answers are the pyramid walk's).
        """
        # One cast at a time in a process: a caster's pool, table and round counter are
        # shared, and numba's default thread pool must not be entered from two threads.
        with _CAST_LOCK:
            return self._checked_cast(origins, directions, max_range, mode, max_hits, coherent)

    def _checked_cast(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        max_range: float | np.ndarray,
        mode: str,
        max_hits: int,
        coherent: bool | None,
    ) -> RayHits:
        o, d, rng = _validate_rays(origins, directions, max_range)
        if coherent not in (None, True, False):
            raise RaycastError(f"coherent must be None, True or False, got {coherent!r}")
        if mode not in ("all", "first"):
            raise RaycastError(f"mode must be 'all' or 'first', got {mode!r}")
        if isinstance(max_hits, bool) or not isinstance(max_hits, int | np.integer) or max_hits < 1:
            raise RaycastError(f"max_hits must be a positive integer, got {max_hits!r}")
        first = mode == "first"
        max_hits = 1 if first else int(max_hits)
        cap = 1 if first else min(FIRST_PASS_HITS, max_hits)
        with _threads_for(len(o)):
            return self._cast(o, d, rng, first, max_hits, cap)

    def _cast(
        self,
        o: np.ndarray,
        d: np.ndarray,
        rng: np.ndarray,
        first: bool,
        max_hits: int,
        cap: int,
    ) -> RayHits:
        """:meth:`cast` once the rays are checked."""
        n = len(o)
        buf, counts, status, crossed, truncated = self._walk_all(o, d, rng, first, max_hits, cap)
        offsets = np.zeros(n + 1, np.int64)
        np.cumsum(counts, out=offsets[1:])
        m = int(offsets[-1])
        range_m = np.empty(m, np.float64)
        points = np.empty((m, 3), np.float64)
        _hk.gather_hits_kernel(buf, counts, offsets, o, d, range_m, points)
        big = np.flatnonzero(counts > cap).astype(np.int64)
        if len(big):  # the same walk again with room for every hit
            sub = self._walk_all(
                np.ascontiguousarray(o[big]),
                np.ascontiguousarray(d[big]),
                np.ascontiguousarray(rng[big]),
                False,
                max_hits,
                max_hits,
            )
            for q, i in enumerate(big.tolist()):
                lo, hi = int(offsets[i]), int(offsets[i + 1])
                range_m[lo:hi] = sub[0][q, : hi - lo]
            _hk.hit_points_kernel(o, d, big, offsets, range_m, points)
        return RayHits(offsets, range_m, points, status, crossed, truncated)

    def _walk_all(
        self,
        o: np.ndarray,
        d: np.ndarray,
        rng: np.ndarray,
        first: bool,
        max_hits: int,
        cap: int,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Every ray walked to its end, loading the blocks they wait for round by round."""
        n = len(o)
        phase = np.zeros(n, np.int8)
        geo = np.empty((n, 7), np.float64)
        fst = np.empty((n, 7), np.float64)
        ist = np.zeros((n, 8), np.int64)
        ist[:, 5] = -1
        need = np.full(n, -1, np.int64)
        buf = np.empty((n, cap), np.float64)
        counts = np.zeros(n, np.int64)
        status = np.empty(n, np.int8)
        crossed = np.zeros(n, bool)
        truncated = np.zeros(n, bool)
        c = self.cache
        outs = (buf, counts, status, crossed, truncated)
        rays = np.arange(n, dtype=np.int64)
        while len(rays):
            self._round += 1
            c.stats.rounds += 1
            with _threads_for(len(rays)):  # a few rays: on this thread (as RayCaster)
                self._launch(o, d, rng, first, max_hits, rays, phase, geo, fst, ist, need, outs)
            waiting = np.flatnonzero(need >= 0)
            if not len(waiting):
                break
            # The blocks most rays wait for first, as many as the pool holds; the rays
            # waiting for the others stay suspended until a later round loads theirs.
            blocks, votes = np.unique(need[waiting], return_counts=True)
            chosen = blocks[np.argsort(-votes, kind="stable")[: c.n_slots]]
            # Read in row-major order: a block's window spans up to nine file tiles, which
            # its neighbours share, so GDAL's block cache serves most of them.
            c.load(np.sort(chosen), self._round)
            rays = waiting[np.isin(need[waiting], chosen)].astype(np.int64)
        walked = phase == 2
        c.stats.visits += int(ist[walked, 6].sum())
        c.stats.misses += int(ist[walked, 7].sum())
        return buf, counts, status, crossed, truncated

    def _launch(
        self,
        o: np.ndarray,
        d: np.ndarray,
        rng: np.ndarray,
        first: bool,
        max_hits: int,
        rays: np.ndarray,
        phase: np.ndarray,
        geo: np.ndarray,
        fst: np.ndarray,
        ist: np.ndarray,
        need: np.ndarray,
        outs: tuple[np.ndarray, ...],
    ) -> None:
        """One round of the kernel over ``rays`` with the cache as it stands."""
        c, g, dem = self.cache, self.grid, self.dem
        buf, counts, status, crossed, truncated = outs
        _tk.tiled_cast_kernel(
            g.nrows, g.ncols, c.tile_level, self.block_max, c.tile_slot, c.pool_elev,
            c.pool_nodes, c.local_off, self.coarse, self.coarse_off, self.lvl_shape,
            dem.holes, float(g.x_min), float(g.y_max), float(g.cell_m), dem.z_min,
            dem.z_max, HEIGHT_MARGIN_M, o, d, rng, first, max_hits, rays, self._round,
            phase, geo, fst, ist, need, c.stamp, buf, counts, status, crossed, truncated,
        )  # fmt: skip
