"""Origin-specific angular index: fast exact ray casting for rays that share an origin.

A camera's pixel rays all leave one point ``O``. In plan view each is a radial line, so it
keeps one azimuth, and its height at horizontal distance ``rho`` from ``O`` is
``O_z + s rho`` with constant slope ``s``. A terrain point is below the ray iff its
angle ``(z - O_z) / rho`` is below ``s``; an above-to-below crossing happens only where
the terrain's angle equals ``s``. The index stores, for polar bins (azimuth x range), a
conservative interval ``[min_angle, max_angle]`` of the terrain's angle over the bin, and
over range, per azimuth bin, a 1-D min/max tree. A ray finds the next range bin whose
interval contains ``s`` in ``O(log n)``, walks the exact patch solver only over such runs
of bins, and skips the rest: near-grazing rays, which the 2-D min/max pyramid must walk
cell by cell near the surface, skip every stretch where the terrain in their thin wedge
stays below them. Results are those of the pyramid walk (same solver on the same
patches; bins never exclude a crossing).

Only the azimuth bins a batch needs are built (a camera sees a sector), in one pass over
the DEM's patches near that sector's annuli; later batches add bins as needed.
:class:`AngularCache` keeps a few origins per DEM (least recently used first out, within a
byte budget). Kernels: ``core.raycast._angular_kernels``; plain-numpy twin:
``core.raycast.reference.angular_leaves_reference``.
"""

from __future__ import annotations

import functools
import threading
from collections import OrderedDict
from dataclasses import dataclass
from types import SimpleNamespace

import numba
import numpy as np

from ..errors import RaycastError
from . import _angular_index_kernels as _ak

__all__ = [
    "DEFAULT_D_RHO_CELLS",
    "DEFAULT_N_AZ",
    "AngularCache",
    "AngularIndex",
    "build_angular_index",
    "index_arrays",
    "needed_azimuth_bins",
    "no_index",
    "tree_levels",
]

#: Azimuth bins over the full circle (pseudo-angle bins, about 1.5 mrad on average).
DEFAULT_N_AZ = 2048
#: Range-bin width in cells.
DEFAULT_D_RHO_CELLS = 2.0
#: Slope classes of the start table (uniform in tan(el) / (1 + |tan(el)|)).
_N_SLOPE_CLASSES = 1024
#: Range chunks per thread when building (load balance across annuli of growing area).
_CHUNKS_PER_THREAD = 32


def tree_levels(n_r: int) -> tuple[np.ndarray, np.ndarray]:
    """Offsets and sizes (int64) of the levels of a 1-D tree over ``n_r`` leaves.

    Level 0 is the leaves; level ``l`` has ``ceil(n_r / 2^l)`` nodes; the last has one.
    """
    sizes = [int(n_r)]
    while sizes[-1] > 1:
        sizes.append((sizes[-1] + 1) // 2)
    size = np.asarray(sizes, np.int64)
    off = np.concatenate([[0], np.cumsum(size)[:-1]]).astype(np.int64)
    return off, size


@dataclass(frozen=True, eq=False)
class AngularIndex:
    """Angle bounds of the terrain seen from one origin, over polar bins.

    Parameters
    ----------
    origin : ndarray, float64, shape (3,)
        ``O`` in the DEM's local frame (m). Only rays with exactly this origin use it.
    gxo, gyo : float
        ``O`` in grid coordinates (fractional column, row of cell centres).
    n_az : int
        Azimuth bins over the full circle (pseudo-angle, see ``core.raycast._angular_kernels``).
    d_rho : float
        Range-bin width (cells of horizontal distance).
    slot_of_az : ndarray, int32, shape (n_az,)
        Row of ``tree`` holding each azimuth bin; -1 where not built.
    tree : ndarray, float32, shape (n_slots, n_nodes, 2)
        Per built azimuth bin: ``[:, 0]`` max and ``[:, 1]`` min terrain angle (m of
        height per cell of distance from ``O``) of every node of the range tree.
    t_off, t_size : ndarray, int64, shape (n_levels,)
        Start and size of each tree level within a slot (level 0 = range bins).
    start : ndarray, int32, shape (n_slots, n_q, 2)
        Per built azimuth bin and slope class (``core.raycast._angular_kernels.slope_class``), the
        first (``[..., 0]``) and last (``[..., 1]``, -1 if none) range bin a ray of that
        class can cross the terrain in.
    s_unit : float
        Slope scale of the classes (the cell size: classes are uniform in
        ``tan(elevation) / (1 + |tan(elevation)|)``).
    """

    origin: np.ndarray
    gxo: float
    gyo: float
    n_az: int
    d_rho: float
    slot_of_az: np.ndarray
    tree: np.ndarray
    t_off: np.ndarray
    t_size: np.ndarray
    start: np.ndarray
    s_unit: float

    @property
    def n_slots(self) -> int:
        """Number of azimuth bins built."""
        return int(self.tree.shape[0])

    @property
    def n_range_bins(self) -> int:
        """Number of range bins (leaves of each tree)."""
        return int(self.t_size[0])

    @property
    def nbytes(self) -> int:
        """Memory held (bytes)."""
        return int(self.tree.nbytes + self.slot_of_az.nbytes + self.start.nbytes)

    def leaves(self, az_bin: int) -> np.ndarray:
        """Leaf bounds ``(n_r, 2)`` (max, min angle) of azimuth bin ``az_bin`` (built)."""
        sl = int(self.slot_of_az[az_bin])
        if sl < 0:
            raise RaycastError(f"azimuth bin {az_bin} is not built")
        return self.tree[sl, : self.n_range_bins]

    def covers(self, want: np.ndarray) -> bool:
        """Whether every azimuth bin flagged in ``want`` (bool, (n_az,)) is built."""
        return bool(np.all(self.slot_of_az[want] >= 0))


def needed_azimuth_bins(
    directions: np.ndarray,
    cell_m: float,
    n_az: int = DEFAULT_N_AZ,
    lo: int = 0,
    hi: int | None = None,
) -> np.ndarray:
    """Azimuth bins (bool mask, (n_az,)) of rays ``lo:hi``, as the cast kernel bins them.

    Parameters
    ----------
    directions : ndarray, float64, shape (n, 3), C-contiguous
        Ray directions, local frame (any non-zero length).
    cell_m : float
        DEM cell size (m).
    """
    d = np.require(directions, np.float64, ["C", "W"])
    want = np.zeros(n_az, bool)
    _ak.azimuth_bins_kernel(d, int(lo), int(len(d) if hi is None else hi), float(cell_m), want)
    return want


def build_angular_index(
    elevation: np.ndarray,
    grid_xy_to_g: tuple[float, float, float],
    origin: np.ndarray,
    want: np.ndarray,
    *,
    margin_m: float,
    n_az: int = DEFAULT_N_AZ,
    d_rho: float = DEFAULT_D_RHO_CELLS,
    base: AngularIndex | None = None,
) -> AngularIndex:
    """Build (or extend ``base`` with) the azimuth bins flagged in ``want``.

    Parameters
    ----------
    elevation : ndarray, float32, shape (nrows, ncols)
        Cell-centre elevations (m), NaN = nodata, C-contiguous.
    grid_xy_to_g : (x_min, y_max, cell_m)
        Georeferencing: ``gx = (x - x_min) / cell - 0.5``, ``gy = (y_max - y) / cell - 0.5``.
    origin : ndarray, float64, shape (3,)
        The rays' common origin (local frame, m).
    want : ndarray, bool, shape (n_az,)
        Azimuth bins to have built.
    margin_m : float
        Height slack (m) added to every bound (``core.raycast.cast.HEIGHT_MARGIN_M``).
    n_az, d_rho : int, float
        Azimuth bins and range-bin width (cells); must match ``base``.
    base : AngularIndex, optional
        An index of the same origin whose built bins are kept.

    Returns
    -------
    AngularIndex
    """
    x_min, y_max, cell = grid_xy_to_g
    o = np.asarray(origin, np.float64).reshape(3).copy()
    gxo = (o[0] - x_min) / cell - 0.5  # as in raycast_kernels._prepare
    gyo = (y_max - o[1]) / cell - 0.5
    nrows, ncols = elevation.shape
    if base is not None:
        if base.n_az != n_az or base.d_rho != d_rho or not np.array_equal(base.origin, o):
            raise RaycastError("cannot extend an angular index of another origin or layout")
        slot_of_az = base.slot_of_az.copy()
        t_off, t_size = base.t_off, base.t_size
        old = base.tree
        old_start = base.start
    else:
        cx = np.array([0.0, ncols - 1.0])
        cy = np.array([0.0, nrows - 1.0])
        far = float(np.sqrt(np.max((cx - gxo) ** 2)[()] + np.max((cy - gyo) ** 2)[()]))
        n_r = int(np.floor(far / d_rho)) + 2
        t_off, t_size = tree_levels(n_r)
        slot_of_az = np.full(n_az, -1, np.int32)
        old = np.empty((0, int(t_size.sum()), 2), np.float32)
        old_start = np.empty((0, _N_SLOPE_CLASSES, 2), np.int32)
    new_bins = np.flatnonzero(np.asarray(want, bool) & (slot_of_az < 0))
    n_old = old.shape[0]
    if len(new_bins) == 0 and base is not None:
        return base
    slot_of_az[new_bins] = np.arange(n_old, n_old + len(new_bins), dtype=np.int32)
    tree = np.empty((n_old + len(new_bins), int(t_size.sum()), 2), np.float32)
    tree[:n_old] = old
    start = np.empty((n_old + len(new_bins),) + old_start.shape[1:], np.int32)
    start[:n_old] = old_start
    n_r = int(t_size[0])
    zmax = np.full((len(new_bins), n_r), -np.inf, np.float32)
    zmin = np.full((len(new_bins), n_r), np.inf, np.float32)
    new_mask = np.zeros(n_az, bool)
    new_mask[new_bins] = True
    threads = numba.get_num_threads()
    _ak.angular_leaves_kernel(
        elevation,
        float(gxo),
        float(gyo),
        int(n_az),
        float(d_rho),
        slot_of_az,
        int(n_old),
        _cone(new_mask),
        threads,
        threads * _CHUNKS_PER_THREAD,
        zmax,
        zmin,
    )
    _ak.angular_tree_kernel(
        zmax,
        zmin,
        float(o[2]),
        float(d_rho),
        float(margin_m),
        float(cell),
        tree,
        t_off,
        t_size,
        start,
        int(n_old),
    )
    del zmax, zmin
    for a in (tree, slot_of_az, start, t_off, t_size):
        a.setflags(write=False)
    return AngularIndex(
        o,
        float(gxo),
        float(gyo),
        int(n_az),
        float(d_rho),
        slot_of_az,
        tree,
        t_off,
        t_size,
        start,
        float(cell),
    )


def _direction(p: float) -> tuple[float, float]:
    """A grid-frame direction whose pseudo-angle is ``p`` (any real, taken mod 4)."""
    p %= 4.0
    if p < 1.0:
        return 1.0 - p, p
    if p < 2.0:
        return 1.0 - p, 2.0 - p
    if p < 3.0:
        return p - 3.0, 2.0 - p
    return p - 3.0, p - 4.0


def _cone(mask: np.ndarray) -> np.ndarray:
    """The narrowest cone holding the flagged azimuth bins, one bin wider each side.

    Returns the ``cone`` argument of ``angular_leaves_kernel``; ``use = 0`` (scan every
    patch) when the bins span half a turn or more.
    """
    n_az = len(mask)
    idx = np.flatnonzero(mask)
    out = np.zeros(6)
    if len(idx) == 0:
        return out
    gaps = (np.roll(idx, -1) - idx) % n_az
    gaps[gaps == 0] = n_az
    k = int(np.argmax(gaps))
    first = int(idx[(k + 1) % len(idx)])
    span = n_az - int(gaps[k]) + 1  # bins from ``first`` (circularly) to the last one
    p0 = (first - 1) * 4.0 / n_az
    p1 = (first + span + 1) * 4.0 / n_az
    if p1 - p0 >= 1.9:  # p differs by 2 between opposite directions
        return out
    if p0 < 0.0:
        p0, p1 = p0 + 4.0, p1 + 4.0
    d0, d1 = _direction(p0), _direction(p1)
    flags = (1 if p1 >= 4.0 or p0 <= 0.0 else 0) | (2 if p0 <= 2.0 <= p1 else 0)
    out[:] = (1.0, d0[0], d0[1], d1[0], d1[1], float(flags))
    return out


class AngularCache:
    """A small thread-safe LRU of angular indexes of one DEM, keyed by origin.

    Parameters
    ----------
    max_origins : int
        Most origins kept.
    max_bytes : int
        Most bytes kept in all (the newest index is always kept).
    """

    def __init__(self, max_origins: int = 16, max_bytes: int = 256 * 1024 * 1024) -> None:
        self.max_origins = int(max_origins)
        self.max_bytes = int(max_bytes)
        self._items: OrderedDict[bytes, AngularIndex] = OrderedDict()
        self._lock = threading.Lock()

    def __len__(self) -> int:
        return len(self._items)

    @property
    def nbytes(self) -> int:
        """Bytes held by the cached indexes."""
        return sum(ix.nbytes for ix in self._items.values())

    def get(self, origin: np.ndarray) -> AngularIndex | None:
        """The index of exactly ``origin`` (float64 (3,)), or None; marks it recently used."""
        key = np.asarray(origin, np.float64).reshape(3).tobytes()
        with self._lock:
            ix = self._items.get(key)
            if ix is not None:
                self._items.move_to_end(key)
            return ix

    def put(self, index: AngularIndex) -> None:
        """Store ``index`` (replacing its origin's older one), evicting the oldest."""
        key = index.origin.tobytes()
        with self._lock:
            self._items[key] = index
            self._items.move_to_end(key)
            while len(self._items) > 1 and (
                len(self._items) > self.max_origins or self.nbytes > self.max_bytes
            ):
                self._items.popitem(last=False)

    def clear(self) -> None:
        """Drop every index."""
        with self._lock:
            self._items.clear()


def index_arrays(
    ix: AngularIndex | SimpleNamespace,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, float, np.ndarray, float]:
    """The index's arrays in the order the angular kernels take them."""
    return (ix.tree, ix.t_off, ix.t_size, ix.slot_of_az, ix.d_rho, ix.start, ix.s_unit)


@functools.cache
def no_index() -> SimpleNamespace:
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
