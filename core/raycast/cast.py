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
thread pool (``numba.set_num_threads``); ``core.warm`` compiles them ahead of use. For a
cold start, :func:`~demtrack.core.raycast.light.use_light_kernels` swaps in quick-to-compile
twins with the same answers (``core.raycast._light_kernels``) until the fast kernels are ready.

The answer's types are in ``core.raycast.hits``, the first pass's scratch in
``core.raycast.scratch``, the re-walk of rays with many hits in ``core.raycast.rewalk``.
"""

from __future__ import annotations

import contextlib
import functools
import threading
import weakref
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, Literal

import numba
import numpy as np

from ..errors import DemError, RaycastError
from ..terrain.grid import GridSpec
from . import _angular_kernels as _ak
from . import _hit_kernels as _hk
from . import _kernels as _k
from . import _light_kernels as _lk
from . import _ray_kernels as _rk
from .angular_index import (
    DEFAULT_N_AZ,
    AngularCache,
    AngularIndex,
    build_angular_index,
    index_arrays,
    needed_azimuth_bins,
    no_index,
)
from .dem_arrays import DemArrays
from .fresh_memory import without_huge_page_advice
from .hits import BELOW_GROUND, HIT, MISS, OUTSIDE, UPWARD, RayHits, RayStatus
from .light import light_kernels, light_kernels_on, use_light_kernels
from .pyramid import MinMaxPyramid, build_pyramid
from .rewalk import recast_light, refill
from .scratch import _FIRST_PASS_HITS, _FIRST_PASS_HITS_RUNS, first_pass_scratch

if TYPE_CHECKING:
    from ..terrain.dem import Dem

__all__ = [
    "BELOW_GROUND",
    "HIT",
    "MISS",
    "HEIGHT_MARGIN_M",
    "MIN_COHERENT_RUN",
    "MIN_ORDERED_RAYS",
    "OUTSIDE",
    "SERIAL_CAST_MAX_RAYS",
    "UPWARD",
    "RayCaster",
    "RayHits",
    "RayStatus",
    "cast_rays",
    "light_kernels",
    "light_kernels_on",
    "use_light_kernels",
]

#: Slack (m) added around the terrain's height range and to every min/max test, so that a
#: surface exactly at a node's max (a flat roof at the global max) is never skipped.
HEIGHT_MARGIN_M = 1e-3
#: Casters of live DEMs (:meth:`RayCaster.for_dem`); an entry goes with its DEM.
_CASTERS: weakref.WeakKeyDictionary[Dem, RayCaster] = weakref.WeakKeyDictionary()
_CASTERS_LOCK = threading.Lock()
#: Shortest run of consecutive rays sharing an origin that ``coherent=None`` casts with an
#: angular index (building one costs about as much as casting ~50k rays without it).
MIN_COHERENT_RUN = 20_000
#: Casts of up to this many rays run on the calling thread: waking the kernels' thread pool
#: costs more than it saves on a few thousand rays (milliseconds per launch on a busy machine
#: against well under a millisecond of work).
SERIAL_CAST_MAX_RAYS = 20_000
#: Batches of at least this many rays without shared origins are cast in an order grouped
#: by origin tile and direction (``core.raycast._ray_kernels.ray_order_kernel``): random rays over a
#: large DEM then find the nodes and cells they walk in cache (the bench's incoherent set:
#: the walk itself 1.8x faster, a whole cast about 1.3x less CPU); below it the sort is not
#: worth its pass.
MIN_ORDERED_RAYS = 20_000


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
        return cls(grid, elev, build_pyramid(elev, use_kernel=not light_kernels_on()))

    @classmethod
    def for_dem(cls, dem: Dem) -> RayCaster:
        """The caster of ``dem``: built on first use, then shared while ``dem`` lives.

        Safe to cache: a :class:`~demtrack.core.terrain.dem.Dem` is frozen and its
        elevation array is read-only. ``cast_rays(dem, ...)`` uses it, so every caller
        shares one min/max pyramid.
        """
        with _CASTERS_LOCK:
            cached = _CASTERS.get(dem)
        if cached is None:
            cached = cls.from_dem(dem)
            with _CASTERS_LOCK:
                cached = _CASTERS.setdefault(dem, cached)
        return cached

    @functools.cached_property
    def kernel_dem(self) -> DemArrays:
        """The grid, elevations and pyramid as the kernels take them (packed once)."""
        return DemArrays.pack(self.grid, self.elevation, self.pyramid, HEIGHT_MARGIN_M)

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
        light = light_kernels_on()
        return self._cast(origins, directions, max_range, mode, max_hits, coherent, light=light)

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
        with first_pass_scratch(n, cap) as (buf, counts):
            return self._cast_into(o, d, rng, first, max_hits, cap, runs, light, buf, counts)

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
        args = (*self.kernel_dem, o, d, rng)
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
            _hk.gather_hits_kernel(buf, counts, offsets, o, d, range_m, points)
            if not first:
                big = np.flatnonzero(counts > cap).astype(np.int64)
                if len(big) and light:
                    recast_light(args, threads, big, max_hits, offsets, range_m, points)
                elif len(big):
                    refill(args, max_hits, big, offsets, range_m, indexed)
                    _hk.hit_points_kernel(o, d, big, offsets, range_m, points)
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
        order = _rk.ray_order_kernel(o, d, rng, *geo, o_s, d_s, rng_s)
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
                nix = index_arrays(no_index())
                _ak.cast_angular_kernel(  # type: ignore[call-arg]
                    *args, first, max_hits, threads, *nix, a, r0, *outs, unbuilt, False
                )
            if r0 < r1:
                ix = self.angular.get(o[r0])
                if ix is None:
                    ix = self._index_for(o[r0], d, r0, r1)
                ixa = index_arrays(ix)
                _ak.cast_angular_kernel(  # type: ignore[call-arg]
                    *args, first, max_hits, threads, *ixa, r0, r1, *outs, unbuilt, True
                )
                indexed.append((r0, r1, ix))
                if unbuilt.any():
                    self._index_for(o[r0], d, r0, r1)
            a = r1
        return indexed


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
    elif _is_frozen_value(dem):
        caster = RayCaster.for_dem(dem)  # a Dem keeps its pyramid: built once, shared
    else:
        caster = RayCaster.from_dem(dem)
    return caster.cast(
        origins, directions, max_range, mode=mode, max_hits=max_hits, coherent=coherent
    )


def _is_frozen_value(dem: Any) -> bool:
    """Whether ``dem`` is a frozen value with identity hashing, like a ``Dem``.

    Its arrays cannot change under a cached caster, and it can key the weak cache. Tested
    by shape, not by importing :class:`~demtrack.core.terrain.dem.Dem`: the terrain package
    is below this one and ``Dem.ray_caster`` calls back here. Other DEM-like values (a
    grid and an elevation array) get a caster of their own.
    """
    kind = type(dem)
    params = getattr(kind, "__dataclass_params__", None)
    return bool(params is not None and params.frozen and kind.__hash__ is object.__hash__)


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
        code, i = _rk.check_rays_kernel(o, d, rng, numba.get_num_threads())
    if code == 1:
        raise RaycastError(f"origins must be finite (ray {i} is not)")
    if code == 2:
        raise RaycastError(f"directions must be finite (ray {i} is not)")
    if code == 3:
        raise RaycastError(f"direction of ray {i} is zero")
    if code == 4:
        raise RaycastError(f"max_range must be >= 0 (inf allowed), not NaN (ray {i})")
    return o, d, rng
