"""Ray casting against the DEM surface: every crossing from above to below, exact.

The surface is the bilinear interpolation of cell-centre elevations (``core.terrain.surface``, the
same function as ``Dem.sample``), defined on the hull of cell centres; a patch with a NaN
corner is a hole that cannot be hit. For each ray this module returns *all* the points
where the ray passes from above the surface to below it, nearest first, each found by
solving the ray/patch quadratic in closed form (no marching), with a hierarchical
Amanatides-Woo walk over a min/max pyramid (``core.raycast.pyramid``, kernels in
``core.raycast._kernels``). ``core.raycast.reference`` is the plain-numpy twin. Runs of
rays sharing one origin (a camera's pixels) instead skip through a per-origin angular
index (``core.raycast.angular_index``) and run the same patch solver only where the terrain's
angle seen from the origin can equal the ray's slope: same answers, faster.

Per-ray status (``RayStatus``), decided in this order:

``OUTSIDE``
    The ray's footprint within ``[0, max_range]`` never meets the DEM domain.
``UPWARD``
    The ray rises or is level (``dz >= 0``) and starts at or above the highest terrain
    cell, so it can never go below the surface. A rising ray that starts lower is walked
    like any other (it may run into a hillside: that is a hit).
``BELOW_GROUND``
    The origin is inside the domain, over a valid patch, strictly under the surface. No
    hits are reported for it (a ray from underground gives no meaningful ground point).
``HIT``
    At least one crossing within ``max_range``.
``MISS``
    Walked, but no crossing before leaving the DEM, going below the lowest terrain or
    reaching ``max_range``.

``crossed_nodata`` is set when the walked part of the ray (inside the domain and within
the terrain's height range, up to the first hit in ``mode="first"``) passes over or
through a hole, so a crossing may be missing. ``truncated`` is set when a ray had more
than ``max_hits`` crossings (only the nearest ``max_hits`` are kept). A ray that enters the
domain from the side already below the surface has no crossing there (the surface has no
walls); it counts crossings only once it has come up above the surface again.

Ranges are metres along the unit direction; points are ``origin + range * unit``. In
``mode="all"`` the kernel keeps the first few hits per ray and re-walks the rare rays with
more, straight into the CSR arrays. Large batches of rays with no shared origin are cast
grouped by origin tile and direction, for locality (same answers). The kernels use numba's
thread pool (``numba.set_num_threads``); :func:`warm_up` compiles them ahead of use. For a
cold start, :func:`use_light_kernels` swaps in quick-to-compile twins with the same answers
(``core.raycast._light_kernels``) until the fast kernels are ready.
"""

from __future__ import annotations

import contextlib
import functools
import threading
from collections.abc import Iterator
from dataclasses import dataclass, field
from enum import IntEnum
from types import SimpleNamespace
from typing import Any, Literal

import numba
import numpy as np

from ..errors import DemError, RaycastError
from ..terrain.grid import GridSpec
from . import _angular_kernels as _ak
from . import _kernels as _k
from . import _light_kernels as _lk
from .angular_index import (
    DEFAULT_N_AZ,
    AngularCache,
    AngularIndex,
    build_angular_index,
    needed_azimuth_bins,
)
from .fresh_memory import without_huge_page_advice
from .pyramid import MinMaxPyramid, build_pyramid

__all__ = [
    "BELOW_GROUND",
    "HIT",
    "MISS",
    "OUTSIDE",
    "UPWARD",
    "RayCaster",
    "RayHits",
    "RayStatus",
    "cast_rays",
    "light_kernels",
    "light_kernels_on",
    "use_light_kernels",
    "warm_up",
]

#: Slack (m) added around the terrain's height range and to every min/max test, so that a
#: surface exactly at a node's max (a flat roof at the global max) is never skipped.
HEIGHT_MARGIN_M = 1e-3
#: Hits kept per ray in the first pass of ``mode="all"``; rays with more are re-walked.
_FIRST_PASS_HITS = 4
#: The same when the batch has runs of one origin (camera rays): their re-walks cost more
#: than the larger buffer (2 % of the bench's camera rays have more than 4 hits, 0.2 %
#: more than 8; re-walking them was ~15 % of an all-hits cast at two threads).
_FIRST_PASS_HITS_RUNS = 8
#: Shortest run of consecutive rays sharing an origin that ``coherent=None`` casts with an
#: angular index (building one costs about as much as casting ~50k rays without it).
MIN_COHERENT_RUN = 20_000
#: Casts of up to this many rays run on the calling thread: waking the kernels' thread pool
#: costs more than it saves on a few thousand rays (milliseconds per launch on a busy machine
#: against well under a millisecond of work).
SERIAL_CAST_MAX_RAYS = 20_000
#: Batches of at least this many rays without shared origins are cast in an order grouped
#: by origin tile and direction (``raycast_kernels.ray_order_kernel``): random rays over a
#: large DEM then find the nodes and cells they walk in cache (the bench's incoherent set:
#: the walk itself 1.8x faster, a whole cast about 1.3x less CPU); below it the sort is not
#: worth its pass.
MIN_ORDERED_RAYS = 20_000
#: First-pass scratch (the hits buffer and counts of a cast) of at least this many bytes
#: is taken from a pool (``_SCRATCH``) instead of allocated: glibc maps blocks above 32 MB
#: afresh on every call (1 M camera rays: 72 MB, 20-40 ms of page faults per all-hits
#: cast), smaller ones it reuses from its heap.
_SCRATCH_MIN_BYTES = 1 << 25
#: Most buffers and bytes the pool keeps between casts (larger buffers are freed).
_SCRATCH_MAX_BUFFERS = 2
_SCRATCH_MAX_BYTES = 256 * 1024 * 1024


class RayStatus(IntEnum):
    """Outcome of one ray (stored as int8 in :attr:`RayHits.status`)."""

    HIT = _k.HIT
    MISS = _k.MISS
    UPWARD = _k.UPWARD
    BELOW_GROUND = _k.BELOW_GROUND
    OUTSIDE = _k.OUTSIDE


HIT = RayStatus.HIT
MISS = RayStatus.MISS
UPWARD = RayStatus.UPWARD
BELOW_GROUND = RayStatus.BELOW_GROUND
OUTSIDE = RayStatus.OUTSIDE


@dataclass(frozen=True, eq=False)
class RayHits:
    """All surface crossings of a batch of rays, in CSR layout.

    Parameters
    ----------
    offsets : ndarray, int64, shape (n + 1,)
        Hits of ray ``i`` are rows ``offsets[i]:offsets[i+1]`` of ``range_m``/``points``.
    range_m : ndarray, float64, shape (m,)
        Distance (m) from the ray origin along the unit direction, increasing per ray.
    points : ndarray, float64, shape (m, 3)
        Crossing points in the DEM's local frame (x east, y north, z up; m).
    status : ndarray, int8, shape (n,)
        :class:`RayStatus` per ray.
    crossed_nodata : ndarray, bool, shape (n,)
        The ray passed over or through a hole, so a crossing may be missing.
    truncated : ndarray, bool, shape (n,)
        The ray had more crossings than ``max_hits``.
    """

    offsets: np.ndarray
    range_m: np.ndarray
    points: np.ndarray
    status: np.ndarray
    crossed_nodata: np.ndarray
    truncated: np.ndarray

    def __post_init__(self) -> None:
        for name in ("offsets", "range_m", "points", "status", "crossed_nodata", "truncated"):
            getattr(self, name).setflags(write=False)

    @property
    def n_rays(self) -> int:
        """Number of rays ``n``."""
        return int(len(self.status))

    @property
    def counts(self) -> np.ndarray:
        """Number of hits per ray, int64 shape (n,)."""
        return np.diff(self.offsets)

    @property
    def hit(self) -> np.ndarray:
        """Boolean mask of rays with at least one hit, shape (n,)."""
        return self.status == HIT

    def first_range_m(self) -> np.ndarray:
        """Range (m) of each ray's nearest hit, NaN where none; shape (n,)."""
        out = np.full(self.n_rays, np.nan)
        has = self.counts > 0
        out[has] = self.range_m[self.offsets[:-1][has]]
        return out

    def first_points(self) -> np.ndarray:
        """Each ray's nearest hit point (local frame, m), NaN rows where none; (n, 3)."""
        out = np.full((self.n_rays, 3), np.nan)
        has = self.counts > 0
        out[has] = self.points[self.offsets[:-1][has]]
        return out

    def hits_of(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """Ranges (k,) and points (k, 3) of ray ``i``'s hits, nearest first."""
        if not -self.n_rays <= i < self.n_rays:
            raise RaycastError(f"ray index {i} out of range for {self.n_rays} rays")
        i %= self.n_rays
        lo, hi = int(self.offsets[i]), int(self.offsets[i + 1])
        return self.range_m[lo:hi], self.points[lo:hi]


class _ScratchPool:
    """A few float64 scratch buffers reused by casts (thread-safe).

    :meth:`take` lends the smallest kept buffer with room for ``size`` items (or a new
    one), :meth:`give` takes it back; at most ``max_buffers`` buffers and ``max_bytes``
    bytes are kept (the smallest go first). A lent buffer belongs to one cast at a time;
    its contents are stale, and no view of it may outlive the cast.
    """

    def __init__(
        self, max_buffers: int = _SCRATCH_MAX_BUFFERS, max_bytes: int = _SCRATCH_MAX_BYTES
    ) -> None:
        self.max_buffers = max_buffers
        self.max_bytes = max_bytes
        self._free: list[np.ndarray] = []
        self._lock = threading.Lock()

    @property
    def nbytes(self) -> int:
        """Bytes kept between casts."""
        with self._lock:
            return sum(b.nbytes for b in self._free)

    def take(self, size: int) -> np.ndarray:
        """A 1-D float64 buffer of at least ``size`` items (uninitialised)."""
        with self._lock:
            fits = [i for i, b in enumerate(self._free) if len(b) >= size]
            if fits:
                return self._free.pop(min(fits, key=lambda i: len(self._free[i])))
        return np.empty(size, np.float64)

    def give(self, buf: np.ndarray) -> None:
        """Return a buffer from :meth:`take` (kept if the bounds allow)."""
        if buf.nbytes > self.max_bytes:
            return
        with self._lock:
            self._free.append(buf)
            self._free.sort(key=len, reverse=True)
            while self._free and (
                len(self._free) > self.max_buffers
                or sum(b.nbytes for b in self._free) > self.max_bytes
            ):
                self._free.pop()

    @contextlib.contextmanager
    def lend(self, size: int) -> Iterator[np.ndarray]:
        """:meth:`take` for the ``with`` block, then :meth:`give`."""
        buf = self.take(size)
        try:
            yield buf
        finally:
            self.give(buf)


#: First-pass scratch shared by all casters (so the memory it keeps is bounded per process).
_SCRATCH = _ScratchPool()


@dataclass(frozen=True, eq=False)
class RayCaster:
    """A DEM prepared for ray casting (its elevation grid and min/max pyramid).

    Build once per DEM with :meth:`from_dem` and reuse: the pyramid costs one pass over
    the grid. ``cast_rays`` accepts either a DEM or a ``RayCaster``. The elevation grid is
    shared when it is a read-only float32 array (``Dem`` makes it so), copied otherwise.
    ``angular`` caches the angular indexes (``core.raycast.angular_index``) of recent ray origins
    (cameras), built on demand by :meth:`cast` and :meth:`prepare_origin`.
    """

    grid: GridSpec
    elevation: np.ndarray
    pyramid: MinMaxPyramid
    angular: AngularCache = field(default_factory=AngularCache, compare=False, repr=False)

    @classmethod
    def from_dem(cls, dem: Any) -> RayCaster:
        """Prepare ``dem`` (anything with ``.grid: GridSpec`` and ``.elevation``)."""
        grid = getattr(dem, "grid", None)
        elevation = getattr(dem, "elevation", None)
        if not isinstance(grid, GridSpec) or elevation is None:
            raise DemError("dem must have a .grid (GridSpec) and an .elevation array")
        elev = np.asarray(elevation)
        # The pyramid describes this grid: keep a private read-only copy unless the caller's
        # array is already a read-only float32 one (as in Dem), which cannot change under us.
        if elev.dtype != np.float32 or elev.flags.writeable or not elev.flags.c_contiguous:
            elev = np.array(elev, dtype=np.float32, order="C")
            elev.setflags(write=False)
        if elev.shape != grid.shape:
            raise DemError(f"elevation has shape {elev.shape}, grid says {grid.shape}")
        if np.isinf(elev).any():
            raise DemError("elevation contains infinite values (nodata must be NaN)")
        return cls(grid, elev, build_pyramid(elev, use_kernel=not _LIGHT.on))

    def prepare_origin(
        self, origin: np.ndarray, directions: np.ndarray | None = None
    ) -> AngularIndex:
        """Build (or extend) and cache the angular index of rays leaving ``origin``.

        Parameters
        ----------
        origin : array_like, float64, shape (3,)
            The rays' common origin (local frame, m).
        directions : array_like, float64, shape (n, 3), optional
            The directions to serve (only their azimuth bins are built); all azimuths
            when omitted.

        Returns
        -------
        AngularIndex
        """
        o = np.require(np.asarray(origin, np.float64).reshape(-1), np.float64, ["C", "W"])
        if o.shape != (3,) or not np.isfinite(o).all():
            raise RaycastError(f"origin must be 3 finite numbers, got {origin!r}")
        if directions is None:
            d = None
        else:
            d = np.require(directions, np.float64, ["C", "W"])
            if d.ndim != 2 or d.shape[1] != 3 or not np.isfinite(d).all():
                raise RaycastError("directions must be a finite (n, 3) array")
        return self._index_for(o, d, 0, 0 if d is None else len(d))

    def _index_for(
        self, origin: np.ndarray, directions: np.ndarray | None, lo: int, hi: int
    ) -> AngularIndex:
        g = self.grid
        base = self.angular.get(origin)
        n_az = base.n_az if base is not None else DEFAULT_N_AZ
        if directions is None:
            want = np.ones(n_az, bool)
        else:
            want = needed_azimuth_bins(directions, g.cell_m, n_az, lo, hi)
        if base is not None and base.covers(want):
            return base
        index = build_angular_index(
            self.elevation,
            (float(g.x_min), float(g.y_max), float(g.cell_m)),
            origin,
            want,
            margin_m=HEIGHT_MARGIN_M,
            n_az=n_az,
            base=base,
        )
        self.angular.put(index)
        return index

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
        """Cast rays; see :func:`cast_rays`."""
        return self._cast(origins, directions, max_range, mode, max_hits, coherent, light=_LIGHT.on)

    def _cast(
        self,
        origins: np.ndarray,
        directions: np.ndarray,
        max_range: float | np.ndarray,
        mode: str,
        max_hits: int,
        coherent: bool | None,
        *,
        light: bool,
    ) -> RayHits:
        """:meth:`cast` with the light (``True``) or fast kernels."""
        o, d, rng = _validate_rays(origins, directions, max_range)
        if coherent not in (None, True, False):
            raise RaycastError(f"coherent must be None, True or False, got {coherent!r}")
        if mode not in ("all", "first"):
            raise RaycastError(f"mode must be 'all' or 'first', got {mode!r}")
        if isinstance(max_hits, bool) or not isinstance(max_hits, int | np.integer) or max_hits < 1:
            raise RaycastError(f"max_hits must be a positive integer, got {max_hits!r}")
        first = mode == "first"
        max_hits = 1 if first else int(max_hits)
        n = len(o)
        # Light kernels: an angular index only when asked for (its kernels are slow to
        # compile); the answers are the same either way.
        runs = np.empty((0, 2), np.int64)
        if n and (coherent or (coherent is None and not light)):
            with _threads_for(n):
                min_run = 1 if coherent else MIN_COHERENT_RUN
                runs = _ak.origin_runs_kernel(o, min_run, numba.get_num_threads())
        keep = _FIRST_PASS_HITS_RUNS if len(runs) else _FIRST_PASS_HITS
        cap = 1 if first else min(keep, max_hits)
        with self._first_pass_scratch(n, cap) as (buf, counts):
            return self._cast_into(o, d, rng, first, max_hits, cap, runs, light, buf, counts)

    @contextlib.contextmanager
    def _first_pass_scratch(self, n: int, cap: int) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """The first pass's hits buffer ``(n, cap)`` and counts ``(n,)``, pooled when large.

        Neither escapes the cast: hits are copied out by the gather, counts summed.
        """
        size = n * (cap + 1)
        if size * 8 < _SCRATCH_MIN_BYTES:
            yield np.empty((n, cap), np.float64), np.empty(n, np.int64)
            return
        with _SCRATCH.lend(size) as raw:
            yield raw[: n * cap].reshape(n, cap), raw[n * cap : size].view(np.int64)

    def _cast_into(
        self,
        o: np.ndarray,
        d: np.ndarray,
        rng: np.ndarray,
        first: bool,
        max_hits: int,
        cap: int,
        runs: np.ndarray,
        light: bool,
        buf: np.ndarray,
        counts: np.ndarray,
    ) -> RayHits:
        """:meth:`_cast` once the rays are checked, with its first-pass scratch."""
        n = len(o)
        status = np.empty(n, np.int8)
        crossed = np.empty(n, bool)
        truncated = np.empty(n, bool)
        g, p = self.grid, self.pyramid
        args = (
            self.elevation,
            p.nodes,
            p.level_offsets,
            p.level_shapes,
            float(g.x_min),
            float(g.y_max),
            float(g.cell_m),
            p.z_min,
            p.z_max,
            HEIGHT_MARGIN_M,
            o,
            d,
            rng,
        )
        with _threads_for(n):
            threads = numba.get_num_threads()
            outs = (buf, counts, status, crossed, truncated)
            indexed: list[tuple[int, int, AngularIndex]] = []
            if len(runs) == 0 and light:
                _lk.cast_kernel_light(*args, first, max_hits, threads, *outs)
            elif len(runs) == 0:
                self._cast_ordered(args, first, max_hits, threads, outs)
            else:
                indexed = self._cast_runs(args, first, max_hits, threads, runs, outs)
            with without_huge_page_advice():
                offsets = np.empty(n + 1, np.int64)
            offsets[0] = 0
            np.cumsum(counts, out=offsets[1:])
            m = int(offsets[-1])
            with without_huge_page_advice():
                range_m = np.empty(m, np.float64)
                points = np.empty((m, 3), np.float64)
            # Hits that fit the first-pass buffer are copied (with their points); the few
            # rays with more are re-walked straight into their CSR slots.
            _k.gather_hits_kernel(buf, counts, offsets, o, d, range_m, points)
            if not first:
                big = np.flatnonzero(counts > cap).astype(np.int64)
                if len(big) and light:
                    _recast_light(args, threads, big, max_hits, offsets, range_m, points)
                elif len(big):
                    _refill(args, max_hits, big, offsets, range_m, indexed)
                    _k.hit_points_kernel(o, d, big, offsets, range_m, points)
        return RayHits(offsets, range_m, points, status, crossed, truncated)

    def _cast_ordered(
        self,
        args: tuple[Any, ...],
        first: bool,
        max_hits: int,
        threads: int,
        outs: tuple[np.ndarray, ...],
    ) -> None:
        """The pyramid walk over rays without shared origins, large batches reordered.

        Rays are cast grouped by origin tile and direction (``ray_order_kernel``):
        random rays over a large DEM then find the nodes and cells they walk in cache.
        The rays are copied into that order as they are sorted, and the kernel writes each
        result to its ray's own row (reading the rays through the permutation inside the
        walk would stall it on memory; stores do not). Each ray's arithmetic is unchanged,
        so are the answers.
        """
        o, d, rng = args[-3:]
        n = len(o)
        if n < MIN_ORDERED_RAYS:
            no_order = np.zeros(0, np.int64)
            _k.cast_kernel(*args, first, max_hits, threads, no_order, *outs)  # type: ignore[call-arg]
            return
        g = self.grid
        o_s, d_s, rng_s = np.empty_like(o), np.empty_like(d), np.empty_like(rng)
        geo = (float(g.x_min), float(g.y_max), float(g.cell_m), *g.shape, threads)
        order = _k.ray_order_kernel(o, d, rng, *geo, o_s, d_s, rng_s)
        _k.cast_kernel(*args[:-3], o_s, d_s, rng_s, first, max_hits, threads, order, *outs)  # type: ignore[call-arg]

    def _cast_runs(
        self,
        args: tuple[Any, ...],
        first: bool,
        max_hits: int,
        threads: int,
        runs: np.ndarray,
        outs: tuple[np.ndarray, ...],
    ) -> list[tuple[int, int, AngularIndex]]:
        """Cast runs of one origin with its angular index, the rays between them without.

        A cached index is used as it is (no per-call pass over the directions); when the
        kernel reports rays whose azimuth bin it lacks (they took the pyramid walk, with
        the same answers) the index is extended for the next batch. Returns the runs and
        the indexes they were cast with.
        """
        o, d = args[-3], args[-2]
        n = len(o)
        unbuilt = np.zeros(threads, np.int64)
        indexed: list[tuple[int, int, AngularIndex]] = []
        a = 0
        for r0, r1 in runs.tolist() + [[n, n]]:
            if a < r0:  # the pyramid walk: the same kernel with no azimuth bin built
                nix = _index_args(_no_index())
                _ak.cast_angular_kernel(  # type: ignore[call-arg]
                    *args, first, max_hits, threads, *nix, a, r0, *outs, unbuilt, False
                )
            if r0 < r1:
                ix = self.angular.get(o[r0])
                if ix is None:
                    ix = self._index_for(o[r0], d, r0, r1)
                ixa = _index_args(ix)
                _ak.cast_angular_kernel(  # type: ignore[call-arg]
                    *args, first, max_hits, threads, *ixa, r0, r1, *outs, unbuilt, True
                )
                indexed.append((r0, r1, ix))
                if unbuilt.any():
                    self._index_for(o[r0], d, r0, r1)
            a = r1
        return indexed


def _recast_light(
    args: tuple[Any, ...],
    threads: int,
    big: np.ndarray,
    max_hits: int,
    offsets: np.ndarray,
    range_m: np.ndarray,
    points: np.ndarray,
) -> None:
    """Light kernels' re-walk: cast rays ``big`` again with room for all their hits.

    The same walk as the first pass, so the same hits; written into their CSR slots.
    Every array has the first pass's dtype and layout: no kernel compiles for this.
    """
    o, d, rng = args[-3:]
    sub = (*args[:-3], o[big], d[big], rng[big])
    nb = len(big)
    buf = np.empty((nb, max_hits), np.float64)
    counts = np.empty(nb, np.int64)
    flags = (np.empty(nb, np.int8), np.empty(nb, bool), np.empty(nb, bool))
    _lk.cast_kernel_light(*sub, False, max_hits, threads, buf, counts, *flags)  # type: ignore[call-arg]
    sub_off = np.zeros(nb + 1, np.int64)
    np.cumsum(counts, out=sub_off[1:])
    m = int(sub_off[-1])
    sub_range = np.empty(m, np.float64)
    sub_points = np.empty((m, 3), np.float64)
    _k.gather_hits_kernel(buf, counts, sub_off, sub[-3], sub[-2], sub_range, sub_points)
    slots = np.repeat(offsets[big] - sub_off[:-1], counts) + np.arange(m)
    range_m[slots] = sub_range
    points[slots] = sub_points


def _refill(
    args: tuple[Any, ...],
    max_hits: int,
    big: np.ndarray,
    offsets: np.ndarray,
    range_m: np.ndarray,
    indexed: list[tuple[int, int, AngularIndex]],
) -> None:
    """Re-walk rays ``big`` (sorted) with all their hits, into their CSR slots.

    Rays of an indexed run take the angular walk they were cast with; the rest the
    pyramid walk. Either way the first pass's walk, so the same hits.
    """
    rest = np.ones(len(big), bool)
    for r0, r1, ix in indexed:
        i0, i1 = np.searchsorted(big, [r0, r1]).tolist()
        if i0 < i1:
            _ak.cast_angular_refill_kernel(  # type: ignore[call-arg]
                *args, max_hits, *_index_args(ix), big[i0:i1], offsets, range_m
            )
            rest[i0:i1] = False
    if rest.any():
        left = big if rest.all() else big[rest]
        _k.cast_all_refill_kernel(*args, max_hits, left, offsets, range_m)  # type: ignore[call-arg]


@contextlib.contextmanager
def _threads_for(n: int) -> Iterator[None]:
    """One numba thread for small casts (the setting is per calling thread; restored)."""
    if n > SERIAL_CAST_MAX_RAYS:
        yield
        return
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(threads)


def _index_args(
    ix: AngularIndex | SimpleNamespace,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, float]:
    return (ix.tree, ix.t_off, ix.t_size, ix.slot_of_az, ix.d_rho, ix.start, ix.s_unit)


@functools.cache
def _no_index() -> SimpleNamespace:
    """Stand-in index with no azimuth bin built: every ray takes the pyramid walk."""
    ix = SimpleNamespace(
        tree=np.zeros((1, 1, 2), np.float32),
        t_off=np.zeros(1, np.int64),
        t_size=np.ones(1, np.int64),
        slot_of_az=np.full(4, -1, np.int32),
        d_rho=1.0,
        start=np.zeros((1, 1, 2), np.int32),
        s_unit=1.0,
    )
    for a in (ix.tree, ix.t_off, ix.t_size, ix.slot_of_az, ix.start):
        a.setflags(write=False)  # as in a built index: one kernel signature
    return ix


def cast_rays(
    dem: Any,
    origins: np.ndarray,
    directions: np.ndarray,
    max_range: float | np.ndarray = np.inf,
    *,
    mode: Literal["all", "first"] = "all",
    max_hits: int = 256,
    coherent: bool | None = None,
) -> RayHits:
    """Find where rays pass from above the DEM surface to below it.

    Parameters
    ----------
    dem : Dem or RayCaster
        Anything with ``.grid`` (:class:`GridSpec`) and ``.elevation`` (float32
        ``(nrows, ncols)``, NaN = nodata, at least 2 x 2), or a prepared
        :class:`RayCaster` (reuses its pyramid).
    origins : array_like, float64, shape (n, 3)
        Ray origins in the DEM's local frame (x east, y north, z up; m).
    directions : array_like, float64, shape (n, 3)
        Ray directions in the same frame; any non-zero length (normalised here).
    max_range : float or array_like shape (n,)
        Maximum range (m along the unit direction), ``>= 0``, may be ``inf``.
    mode : {"all", "first"}
        ``"all"``: every crossing, nearest first; ``"first"``: stop at the nearest one.
    max_hits : int
        Most crossings kept per ray in ``mode="all"`` (nearest first); more sets
        ``truncated``.
    coherent : bool or None
        Use per-origin angular indexes (``core.raycast.angular_index``) for runs of consecutive
        rays sharing one origin (a camera's pixels): ``None`` for runs of at least
        ``MIN_COHERENT_RUN`` rays, ``True`` for every run, ``False`` never. Answers are
        the same either way (to rounding, well under 1e-9 m); only speed differs. The
        indexes are cached on the caster (a ``Dem`` shares one caster).

    Returns
    -------
    RayHits
        Hits exact to well under 1 mm (closed-form roots in float64); see the module
        docstring for the status rules.

    Raises
    ------
    RaycastError
        On malformed rays, range, mode or max_hits.
    DemError
        On an unusable DEM (no grid, shape mismatch, infinite values, smaller than 2 x 2
        or without any finite elevation).
    """
    if isinstance(dem, RayCaster):
        caster = dem
    elif callable(getattr(dem, "ray_caster", None)):
        caster = dem.ray_caster()  # a Dem keeps its pyramid: built once, shared
    else:
        caster = RayCaster.from_dem(dem)
    return caster.cast(
        origins, directions, max_range, mode=mode, max_hits=max_hits, coherent=coherent
    )


class _LightState:
    """Whether casts use the light kernels (``core.raycast._light_kernels``)."""

    on = False


_LIGHT = _LightState()


def use_light_kernels(enabled: bool = True) -> None:
    """Cast with the light kernels (``True``) or the fast ones (``False``, the default).

    The light kernels give the same answers bit for bit and compile in well under half the
    time; they cast on one thread (releasing the GIL), a new caster builds its min/max
    pyramid in plain numpy, and ``coherent=None`` builds no angular index
    (``coherent=True`` still does). For a process whose numba cache is cold and that
    needs answers before the fast kernels could compile (the sample-site build's renders,
    ``demtrack demo`` until its warm-up is done). Process-wide; :func:`warm_up` turns them
    off once the fast kernels are ready.
    """
    _LIGHT.on = bool(enabled)


def light_kernels_on() -> bool:
    """Whether casts use the light kernels (see :func:`use_light_kernels`)."""
    return _LIGHT.on


@contextlib.contextmanager
def light_kernels() -> Iterator[None]:
    """Cast with the light kernels inside the block; the previous choice after it."""
    before = _LIGHT.on
    _LIGHT.on = True
    try:
        yield
    finally:
        _LIGHT.on = before


def warm_up(angular: bool = True) -> None:
    """Compile (or load from numba's on-disk cache) every kernel, on a tiny DEM.

    The server calls this at start-up so the first real request does not pay for
    compilation (about 25 s of CPU cold for the pyramid kernels, about 60 s more for the
    angular-index kernels; well under a second from the cache).

    Parameters
    ----------
    angular : bool
        Also compile the angular-index kernels, used only by casts of at least
        ``MIN_COHERENT_RUN`` rays from one origin (or ``coherent=True``), and the sort of
        batches of at least ``MIN_ORDERED_RAYS`` rays without shared origins.

    Notes
    -----
    It always warms the fast kernels, then turns the light ones off
    (:func:`use_light_kernels`): casts switch to the fast kernels once they are ready.
    """
    elev = np.arange(16, dtype=np.float32).reshape(4, 4)
    elev[0, 0] = np.nan
    build_pyramid(elev)  # the kernel, even while light kernels are on
    caster = RayCaster.from_dem(SimpleNamespace(grid=GridSpec(0.0, 4.0, 1.0, 4, 4), elevation=elev))
    o = np.array([[2.0, 2.0, 100.0], [0.5, 3.5, 100.0]])
    d = np.array([[0.1, 0.1, -1.0], [0.0, 0.0, -1.0]])
    caster._cast(o, d, np.inf, "first", 256, None, light=False)
    caster._cast(o, d, np.inf, "all", 8, None, light=False)
    if angular:
        # The angular-index path (camera rays): build, cast, and the pyramid walk between
        # runs; and the sort of large incoherent batches. Both serve only batches of at
        # least 20,000 rays, which the server's requests are not: it warms without them
        # (about 7 s of CPU less in a cold start).
        _warm_angular(caster)
        g, rng = caster.grid, np.full(len(o), np.inf)
        copies = (np.empty_like(o), np.empty_like(d), np.empty_like(rng))
        geo = (float(g.x_min), float(g.y_max), float(g.cell_m), *g.shape, 1)
        _k.ray_order_kernel(o, d, rng, *geo, *copies)
    # A level ray over a zig-zag crosses more often than the first pass keeps: this
    # compiles the re-walk kernel too.
    _zigzag_cast(None)
    use_light_kernels(False)


def _zigzag_cast(coherent: bool | None) -> None:
    """A level ray over a zig-zag: 12 crossings, more than either first pass keeps."""
    zig = np.tile(np.array([0.0, 10.0], np.float32), 12)
    zigzag = SimpleNamespace(grid=GridSpec(0.0, 2.0, 1.0, 2, 24), elevation=np.vstack([zig, zig]))
    RayCaster.from_dem(zigzag)._cast(
        np.array([[0.5, 1.0, 5.0]]),
        np.array([[1.0, 0.0, 0.0]]),
        np.inf,
        "all",
        256,
        coherent,
        light=False,
    )


def _warm_angular(caster: RayCaster) -> None:
    """Compile the angular-index kernels (build, cast, the walk between runs, re-walk)."""
    o3 = np.array([[2.0, 2.0, 100.0], [2.0, 2.0, 100.0], [0.5, 3.5, 100.0]])
    d3 = np.array([[0.1, 0.1, -1.0], [0.2, -0.1, -1.0], [0.0, 0.0, -1.0]])
    caster._cast(o3, d3, np.inf, "first", 256, True, light=False)
    caster._cast(o3, d3, np.inf, "all", 8, True, light=False)
    _zigzag_cast(True)


def _validate_rays(
    origins: Any, directions: Any, max_range: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    try:
        # Writable C arrays always, so the kernels are compiled for one signature only.
        o = np.require(origins, np.float64, ["C", "W"])
        d = np.require(directions, np.float64, ["C", "W"])
    except (TypeError, ValueError) as exc:
        raise RaycastError(f"origins and directions must be numeric arrays: {exc}") from None
    if o.ndim != 2 or o.shape[1] != 3:
        raise RaycastError(f"origins must have shape (n, 3), got {o.shape}")
    if d.shape != o.shape:
        raise RaycastError(f"directions must have shape {o.shape}, got {d.shape}")
    try:
        rng = np.broadcast_to(np.asarray(max_range, dtype=np.float64), (len(o),))
    except (TypeError, ValueError):
        raise RaycastError(f"max_range must be a number or an array of shape ({len(o)},)") from None
    # A fresh writable C array always, so the kernels see one signature only.
    rng = np.array(rng, dtype=np.float64)
    with _threads_for(len(o)):
        code, i = _k.check_rays_kernel(o, d, rng, numba.get_num_threads())
    if code == 1:
        raise RaycastError(f"origins must be finite (ray {i} is not)")
    if code == 2:
        raise RaycastError(f"directions must be finite (ray {i} is not)")
    if code == 3:
        raise RaycastError(f"direction of ray {i} is zero")
    if code == 4:
        raise RaycastError(f"max_range must be >= 0 (inf allowed), not NaN (ray {i})")
    return o, d, rng
