"""Decoded blocks of a tiled DEM in a fixed pool of slots, least recently used evicted.

A slot holds one patch block of ``core.terrain.tiled_dem``: its cells with a one-cell halo
(``(tile + 2)**2`` float32) and its own min/max pyramid levels ``1 .. T-1`` (built on load
with ``core.raycast.pyramid``, in a fixed layout: level ``k`` is ``(tile >> k)**2`` nodes).
The pool is as many slots as ``memory_budget`` bytes hold (at most one per block); its
pages are touched only as slots fill, so memory grows with what rays visit, never past the
budget. ``tile_slot[by, bx]`` is the slot of a resident block or -1: the table the
casting kernel (``core.raycast._tiled_walk_kernels``) reads.

Blocks are read by several threads at once (the tiled DEM keeps one dataset handle per
thread); the pyramids are built on the calling thread.
"""

from __future__ import annotations

import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np

from ..errors import DemError, RaycastError
from ..terrain.tiled_dem import TiledDem
from .cast import _threads_for
from .pyramid import build_pyramid

__all__ = ["CacheStats", "TileCache", "slot_bytes"]

#: Threads reading blocks (GDAL decodes DEFLATE/ZSTD with the GIL released).
READ_THREADS = 2


def _local_offsets(tile_level: int) -> np.ndarray:
    """Offsets of levels ``1 .. T-1`` in a slot's node table (level ``k``: ``(tile >> k)**2``)."""
    sizes = [(1 << (tile_level - k)) ** 2 for k in range(1, tile_level)]
    return (
        np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        if sizes
        else np.zeros(0, np.int64)
    )


def slot_bytes(tile: int) -> int:
    """Bytes one slot of a ``tile``-cell block holds (cells with halo, plus its levels)."""
    tile_level = tile.bit_length() - 1
    nodes = sum((1 << (tile_level - k)) ** 2 for k in range(1, tile_level))
    return (tile + 2) ** 2 * 4 + max(nodes, 1) * 8


@dataclass
class CacheStats:
    """Counters of a :class:`TileCache` (since it was made).

    Attributes
    ----------
    loads : int
        Blocks read from the file and decoded.
    evictions : int
        Resident blocks dropped to make room.
    visits : int
        Times a ray's walk entered a block below the coarse levels.
    misses : int
        Of those, the times the block was not resident (the ray waited for a load).
    load_s : float
        Wall-clock seconds spent loading blocks (reading, decoding, building levels).
    rounds : int
        Kernel launches (each resumes the rays whose blocks were just loaded).
    """

    loads: int = 0
    evictions: int = 0
    visits: int = 0
    misses: int = 0
    load_s: float = 0.0
    rounds: int = 0

    @property
    def hits(self) -> int:
        """Block entries served from the cache (``visits - misses``)."""
        return self.visits - self.misses


class TileCache:
    """An LRU pool of decoded blocks of one :class:`TiledDem` under a memory budget.

    Parameters
    ----------
    dem : TiledDem
    memory_budget : int
        Bytes the slots may hold (at least one slot, :func:`slot_bytes`).
    """

    def __init__(self, dem: TiledDem, memory_budget: int) -> None:
        if isinstance(memory_budget, bool) or not isinstance(memory_budget, int | np.integer):
            raise RaycastError(f"memory_budget must be a number of bytes, got {memory_budget!r}")
        per = slot_bytes(dem.tile)
        if memory_budget < per:
            raise RaycastError(
                f"memory budget of {int(memory_budget)} bytes is below one "
                f"{dem.tile} x {dem.tile} tile ({per} bytes)"
            )
        self.dem = dem
        self.tile_level = dem.tile.bit_length() - 1
        nby, nbx = dem.minmax.shape[:2]
        self.n_slots = int(min(memory_budget // per, nby * nbx))
        self.memory_budget = int(memory_budget)
        t = dem.tile
        self.local_off = _local_offsets(self.tile_level)
        n_local = max(int(sum((t >> k) ** 2 for k in range(1, self.tile_level))), 1)
        # np.empty maps the pool without touching it: pages are committed as slots fill.
        self.pool_elev = np.empty((self.n_slots, t + 2, t + 2), np.float32)
        self.pool_nodes = np.empty((self.n_slots, n_local, 2), np.float32)
        self.tile_slot = np.full((nby, nbx), -1, np.int32)
        self.stamp = np.zeros(self.n_slots, np.int64)
        self._block_of = np.full(self.n_slots, -1, np.int64)
        self._used = 0
        self._pool: ThreadPoolExecutor | None = None
        self.stats = CacheStats()

    @property
    def resident_bytes(self) -> int:
        """Bytes of the slots filled so far (never more than the budget)."""
        return self._used * slot_bytes(self.dem.tile)

    def load(self, blocks: np.ndarray, now: int) -> None:
        """Make ``blocks`` (int64 ``by * block_cols + bx``, at most ``n_slots``) resident.

        Slots are taken free first, then from the blocks used longest ago (their
        ``stamp``, set by the kernel), never from the ones being loaded.
        """
        t0 = time.perf_counter()
        blocks = np.asarray(blocks, np.int64)
        nbx = self.tile_slot.shape[1]
        todo = [int(b) for b in blocks if self.tile_slot[b // nbx, b % nbx] < 0]
        if len(todo) > self.n_slots:
            raise RaycastError(f"{len(todo)} blocks asked for at once, the pool has {self.n_slots}")
        free = list(range(self._used, min(self.n_slots, self._used + len(todo))))
        self._used += len(free)
        if len(free) < len(todo):
            keep = set(todo)
            held = [
                s for s in np.argsort(self.stamp, kind="stable").tolist() if self._block_of[s] >= 0
            ]
            for s in held:
                if len(free) == len(todo):
                    break
                b = int(self._block_of[s])
                if b in keep:
                    continue
                self.tile_slot[b // nbx, b % nbx] = -1
                self._block_of[s] = -1
                self.stats.evictions += 1
                free.append(s)
        pairs = list(zip(todo, free, strict=True))
        owners = {b: s for b, s in pairs}
        # First every new block's own cells (one file tile each), then the edge rows and
        # columns its patches reach into, copied from the blocks that own them when those
        # are resident (new or old) and read from the file only otherwise: a block's
        # window spans up to nine file tiles, and GDAL decodes whole tiles.
        if self._pool is None:  # kept: each reader thread opens the file once
            self._pool = ThreadPoolExecutor(READ_THREADS, thread_name_prefix="tile-read")
        list(self._pool.map(lambda p: self._read_own(p[0], p[1]), pairs))
        shapes = list(self._pool.map(lambda p: self._read_edges(p[0], p[1], owners), pairs))
        for (b, s), shape in zip(pairs, shapes, strict=True):
            self._build_levels(s, shape)
            self._block_of[s] = b
            self.stamp[s] = now
            self.tile_slot[b // nbx, b % nbx] = s
        self.stats.loads += len(pairs)
        self.stats.load_s += time.perf_counter() - t0

    def _read_own(self, block: int, slot: int) -> None:
        """The cells block ``block`` owns (its file tile) into ``slot``; the rest NaN."""
        g, t = self.dem.grid, self.dem.tile
        by, bx = divmod(block, self.tile_slot.shape[1])
        r0, c0 = by * t, bx * t
        r1, c1 = min(r0 + t, g.nrows), min(c0 + t, g.ncols)
        out = self.pool_elev[slot]
        out.fill(np.nan)
        out[1 : 1 + r1 - r0, 1 : 1 + c1 - c0] = self.dem.read_cells(r0, r1, c0, c1)

    def _read_edges(self, block: int, slot: int, owners: dict[int, int]) -> tuple[int, int]:
        """The next row and column of ``block`` (and, with holes, its halo); its cell shape.

        The halo (the row and column before the block) is read only when the DEM has
        holes: only a hole's grid-line neighbour reads it.
        """
        g, t = self.dem.grid, self.dem.tile
        by, bx = divmod(block, self.tile_slot.shape[1])
        r0, c0 = by * t, bx * t
        self._fill(slot, r0, c0, r0 + t, r0 + t + 1, c0, c0 + t + 1, owners)
        self._fill(slot, r0, c0, r0, r0 + t, c0 + t, c0 + t + 1, owners)
        if self.dem.holes:
            self._fill(slot, r0, c0, r0 - 1, r0, c0 - 1, c0 + t + 1, owners)
            self._fill(slot, r0, c0, r0, r0 + t + 1, c0 - 1, c0, owners)
        return min(r0 + t + 1, g.nrows) - r0, min(c0 + t + 1, g.ncols) - c0

    def _fill(
        self,
        slot: int,
        r_org: int,
        c_org: int,
        r_lo: int,
        r_hi: int,
        c_lo: int,
        c_hi: int,
        owners: dict[int, int],
    ) -> None:
        """Cells ``[r_lo:r_hi, c_lo:c_hi]`` (clipped to the grid) into ``slot``.

        Cell ``(r, c)`` goes to ``[r - r_org + 1, c - c_org + 1]``. Each part comes from
        the block that owns it (the one whose file tile holds it) when that is resident,
        else from the file.
        """
        g, t = self.dem.grid, self.dem.tile
        nby, nbx = self.tile_slot.shape
        r_lo, r_hi = max(r_lo, 0), min(r_hi, g.nrows)
        c_lo, c_hi = max(c_lo, 0), min(c_hi, g.ncols)
        out = self.pool_elev[slot]
        for oy in range(r_lo // t, (r_hi - 1) // t + 1) if r_lo < r_hi else ():
            for ox in range(c_lo // t, (c_hi - 1) // t + 1) if c_lo < c_hi else ():
                a0, a1 = max(r_lo, oy * t), min(r_hi, oy * t + t)
                b0, b1 = max(c_lo, ox * t), min(c_hi, ox * t + t)
                src = -1
                if oy < nby and ox < nbx:
                    src = owners.get(oy * nbx + ox, int(self.tile_slot[oy, ox]))
                dst = out[a0 - r_org + 1 : a1 - r_org + 1, b0 - c_org + 1 : b1 - c_org + 1]
                if src >= 0:
                    own = self.pool_elev[src]
                    dst[...] = own[
                        a0 - oy * t + 1 : a1 - oy * t + 1, b0 - ox * t + 1 : b1 - ox * t + 1
                    ]
                else:
                    dst[...] = self.dem.read_cells(a0, a1, b0, b1)

    def _build_levels(self, slot: int, shape: tuple[int, int]) -> None:
        """Fill the slot's levels ``1 .. T-1`` from its cells (``shape``: rows, cols)."""
        nodes = self.pool_nodes[slot]
        if self.tile_level <= 1:
            return
        cells = self.pool_elev[slot, 1 : 1 + shape[0], 1 : 1 + shape[1]]
        try:
            # One block is a millisecond of work on one thread; waking numba's pool for it
            # cost 100-200 ms a block on the loaded two-core machine.
            with _threads_for(0):
                pyr = build_pyramid(cells)
        except DemError:  # every cell a hole: nothing can be hit, nothing skipped
            nodes[:, 0] = np.inf
            nodes[:, 1] = -np.inf
            return
        for k in range(1, self.tile_level):
            side = 1 << (self.tile_level - k)
            start = int(self.local_off[k - 1])
            view = nodes[start : start + side * side].reshape(side, side, 2)
            # Past the block's own top every level is its single root node.
            lv = pyr.level(min(k, pyr.n_levels))
            view[: lv.shape[0], : lv.shape[1]] = lv
