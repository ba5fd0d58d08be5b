"""Benchmark: camera rays over a DEM larger than memory, under a memory budget.

A synthetic terrain of ``--size`` x ``--size`` cells (1 m) is written as a tiled DEM
(``demtrack dem synth``; reused when the file is already there; free disk checked first).
Cameras stand 40 m above the terrain on a grid over the whole DEM; each casts a fan of
pixel rays (every azimuth, depression 1 .. 25 degrees, 2.5 km range), all in one batch, with
:class:`~demtrack.core.raycast.tiled_cast.TiledRayCaster` whose block pool gets what is left of
``--budget-mb`` once the process's own memory (interpreter, compiled kernels, the rays'
state, GDAL's block cache) is counted. The peak RSS of the cast (Linux ``VmHWM``, reset
once the kernels are compiled) is checked against the budget, before any reference is
built; the process's lifetime peak (``getrusage``, compilation included) is printed too.

References, measured in the same run: each camera's window (the patch blocks of its 2.5 km
reach) read into memory and cast with the in-memory ``RayCaster`` kernels in the whole DEM's
frame (:class:`~demtrack.core.raycast.window_cast.WindowRayCaster`: the whole grid's origin
and height range, the window's cells and pyramid aligned to the file's blocks, the coarse
levels from its block min/max): offsets, ranges, points, statuses and flags must be equal
bit for bit. With ``--full-reference``
(default when the DEM fits in 1 GB; above that its cells go to a raw read-only memmap
beside the DEM, deleted after) the whole DEM is also cast by the in-memory ``RayCaster``,
where the answers must be equal bit for bit.

Usage: ``demtrack bench large-dem [--size 4000] [--budget-mb 576] [--dem PATH]``; the bar
of issue 30 is ``--size 40000 --budget-mb 2048``.
"""

from __future__ import annotations

import argparse
import resource
import shutil
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import psutil

from demtrack.core.raycast import _hit_kernels as _hk
from demtrack.core.raycast.cast import RayCaster, RayHits
from demtrack.core.raycast.tiled_cast import TiledRayCaster
from demtrack.core.raycast.window_cast import WindowRayCaster
from demtrack.core.terrain.tiled_dem import GDAL_CACHE_MB, TiledDem
from demtrack.core.terrain.tiled_write import synth_tiled

__all__ = ["camera_rays", "main"]

RANGE_M = 2500.0
#: Bytes per ray of the tiled cast's state and answer (walk state, first-pass hits, CSR).
_BYTES_PER_RAY = 600


def _peak_rss_mb() -> float:
    """The process's lifetime peak RSS (MiB), compiling the kernels included."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def _reset_hwm() -> bool:
    """Reset the kernel's peak-RSS mark (Linux ``clear_refs`` 5); False where unsupported."""
    try:
        Path("/proc/self/clear_refs").write_text("5")
    except OSError:
        return False
    return True


def _hwm_mb() -> float:
    """Peak RSS (MiB) since :func:`_reset_hwm` (``VmHWM``), else the lifetime peak."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return float(line.split()[1]) / 1024.0
    except OSError:
        pass
    return _peak_rss_mb()


def _rss_mb() -> float:
    return psutil.Process().memory_info().rss / 2**20


def camera_rays(
    td: TiledDem, n_side: int, az: int, el: int
) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int]]]:
    """Cameras on an ``n_side x n_side`` grid over the DEM, 40 m up; their pixel rays.

    Returns origins, directions (each ``(n_side**2 * az * el, 3)``, camera after camera)
    and each camera's rows ``(lo, hi)``.
    """
    g = td.grid
    frac = (np.arange(n_side) + 0.5) / n_side
    xs = g.x_min + frac * g.ncols * g.cell_m
    ys = g.y_max - frac * g.nrows * g.cell_m
    a, e = np.meshgrid(
        np.linspace(0, 2 * np.pi, az, endpoint=False), np.radians(np.linspace(-25, -1, el))
    )
    d1 = np.c_[(np.cos(e) * np.cos(a)).ravel(), (np.cos(e) * np.sin(a)).ravel(), np.sin(e).ravel()]
    origins, dirs, spans = [], [], []
    for y in ys:
        for x in xs:
            z = float(td.sample(np.array([x]), np.array([y]))[0]) + 40.0
            lo = sum(len(o) for o in origins)
            origins.append(np.tile([x, y, z], (len(d1), 1)))
            dirs.append(d1)
            spans.append((lo, lo + len(d1)))
    return np.concatenate(origins), np.concatenate(dirs), spans


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark and print its report; returns the exit status (1 on a mismatch)."""
    p = argparse.ArgumentParser(prog="demtrack bench large-dem", description=__doc__.split("\n")[0])
    p.add_argument("--size", type=int, default=4000, help="DEM rows = columns (default 4000)")
    p.add_argument("--budget-mb", type=float, default=576.0, help="process budget (MiB)")
    p.add_argument("--tile", type=int, default=512, help="tile side (cells)")
    p.add_argument("--cameras", type=int, default=3, help="cameras per side of the grid")
    p.add_argument("--dem", type=Path, help="tiled DEM file (default: a temporary folder)")
    p.add_argument("--full-reference", action=argparse.BooleanOptionalAction, default=None)
    args = p.parse_args(argv)
    tmp = None
    if args.dem is None:
        tmp = tempfile.TemporaryDirectory(prefix="demtrack-large-dem-")
        args.dem = Path(tmp.name) / f"synth-{args.size}.tif"
    try:
        return _run(args)
    finally:
        if tmp is not None:
            tmp.cleanup()


def _run(args: argparse.Namespace) -> int:
    size = args.size
    raw_gb = size * size * 4 / 1e9
    free_gb = shutil.disk_usage(args.dem.parent).free / 1e9
    print(f"DEM {size} x {size} = {size * size / 1e9:.2f} G cells ({raw_gb:.1f} GB as float32)")
    print(f"free disk at {args.dem.parent}: {free_gb:.1f} GB")
    t0 = time.perf_counter()
    if args.dem.is_file() and TiledDem.open(args.dem).grid.shape == (size, size):
        td = TiledDem.open(args.dem)
        print(f"reusing {args.dem}")
    else:
        if free_gb < 1.6 * raw_gb:  # the streamed file and its COG, as `dem synth` checks
            print(f"not enough free disk for {args.dem}")
            return 1
        td = synth_tiled(args.dem, size, tile=args.tile, compress="zstd")
        print(f"wrote {args.dem} in {time.perf_counter() - t0:.0f} s")
    gb = args.dem.stat().st_size / 1e9
    print(f"file {gb:.2f} GB, tiles {td.tile}, z {td.z_min:.1f} .. {td.z_max:.1f} m")
    o, d, spans = camera_rays(td, args.cameras, 360, 60)
    n = len(o)
    # Compile the kernels on one camera's rays (every path: re-walks of rays with many
    # hits too), then count what the process holds already.
    TiledRayCaster(td, 8 * (td.tile + 2) ** 2 * 8).cast(o[: spans[0][1]], d[: spans[0][1]], RANGE_M)
    _hk.hit_points_kernel(
        o[:1], d[:1], np.zeros(1, np.int64), np.zeros(2, np.int64), np.zeros(0), np.zeros((0, 3))
    )
    base_mb = _rss_mb()
    reset = _reset_hwm()
    pool_mb = args.budget_mb - base_mb - GDAL_CACHE_MB - n * _BYTES_PER_RAY / 2**20
    if pool_mb <= 0:
        own = args.budget_mb - pool_mb
        print(f"budget of {args.budget_mb:.0f} MiB leaves nothing for blocks ({own:.0f} MiB own)")
        return 1
    tc = TiledRayCaster(td, int(pool_mb * 2**20))
    t1 = time.perf_counter()
    got = tc.cast(o, d, RANGE_M)
    dt = time.perf_counter() - t1
    peak = _hwm_mb() if reset else _peak_rss_mb()
    lifetime = _peak_rss_mb()
    s = tc.stats
    nb = td.minmax.shape[0] * td.minmax.shape[1]
    print(f"{args.cameras**2} cameras, {n} rays, {int(got.hit.sum())} hit, {len(got.range_m)} hits")
    print(
        f"tiled cast: {dt:.2f} s ({n / dt:,.0f} rays/s); blocks loaded {s.loads} of {nb}, "
        f"evicted {s.evictions}, block entries {s.visits} ({s.hits} from the cache)"
    )
    print(
        f"  of which loading blocks {s.load_s:.2f} s ({s.load_s / dt:.0%}), "
        f"{s.load_s / max(s.loads, 1) * 1e3:.1f} ms a block; {s.rounds} kernel rounds"
    )
    print(
        f"memory: process before the cast {base_mb:.0f} MiB, block pool {pool_mb:.0f} MiB "
        f"({tc.cache.n_slots} slots, {tc.cache.resident_bytes / 2**20:.0f} MiB filled)"
    )
    holds = peak <= args.budget_mb
    verdict = "holds" if holds else "EXCEEDED"
    print(f"peak RSS {peak:.0f} MiB, budget {args.budget_mb:.0f} MiB: {verdict}")
    print(f"(process lifetime peak, compiling the kernels included: {lifetime:.0f} MiB)")
    ok = holds and _windowed_check(td, o, d, spans, got)
    full = args.full_reference if args.full_reference is not None else raw_gb <= 1.0
    if full:
        _reset_hwm()
        ok = _full_check(td, o, d, got) and ok
    return 0 if ok else 1


def _windowed_check(
    td: TiledDem, o: np.ndarray, d: np.ndarray, spans: list[tuple[int, int]], got: RayHits
) -> bool:
    """Each camera's window cast in memory, in the whole DEM's frame: bit for bit the tiled cast."""
    same = True
    bit_equal = 0
    t_ref = 0.0
    cells = 0
    for lo, hi in spans:
        win = WindowRayCaster.for_rays(td, o[lo:hi], d[lo:hi], RANGE_M)
        r0, r1, c0, c1 = win.window
        cells = max(cells, (r1 - r0) * (c1 - c0))
        t = time.perf_counter()
        want = win.cast(o[lo:hi], d[lo:hi], RANGE_M)
        t_ref += time.perf_counter() - t
        a, b = got.offsets[lo], got.offsets[hi]
        mine = RayHits(
            got.offsets[lo : hi + 1] - a,
            got.range_m[a:b],
            got.points[a:b],
            got.status[lo:hi],
            got.crossed_nodata[lo:hi],
            got.truncated[lo:hi],
        )
        same &= _identical(want, mine)
        if np.array_equal(want.offsets, mine.offsets):
            bit_equal += int(np.sum(np.all(want.points == mine.points, axis=1)))
        del win
    m = len(got.range_m)
    print(
        f"windowed in-memory RayCaster (whole DEM's frame, windows up to {cells / 1e6:.1f} M "
        f"cells): {'bit-identical' if same else 'DIFFERENT'}; {bit_equal} of {m} hit points "
        f"bit-equal; cast {t_ref:.2f} s (window reads and pyramids not counted)"
    )
    return same


def _identical(a: RayHits, b: RayHits) -> bool:
    """Whether two answers are equal bit for bit, every array."""
    return all(
        np.array_equal(getattr(a, f), getattr(b, f))
        for f in ("offsets", "range_m", "points", "status", "crossed_nodata", "truncated")
    )


def _full_check(td: TiledDem, o: np.ndarray, d: np.ndarray, got: RayHits) -> bool:
    """The whole DEM cast by ``RayCaster``; above 1 GB its cells are a read-only memmap.

    The memmap (a raw float32 copy beside the DEM, deleted after) lets the in-memory
    caster run on a DEM that does not fit: the pages are the kernel's page cache, the
    pyramid (a third of the cells) is in memory.
    """
    g = td.grid
    raw = td.path.with_name(td.path.name + ".raw.f32")
    try:
        if g.nrows * g.ncols * 4 <= 1 << 30:
            elev = td.read_cells(0, g.nrows, 0, g.ncols)
        else:
            mm = np.memmap(raw, np.float32, "w+", shape=g.shape)
            for r0 in range(0, g.nrows, td.tile):
                r1 = min(r0 + td.tile, g.nrows)
                mm[r0:r1] = td.read_cells(r0, r1, 0, g.ncols)
            mm.flush()
            del mm
            elev = np.memmap(raw, np.float32, "r", shape=g.shape)
        t = time.perf_counter()
        caster = RayCaster.from_dem(SimpleNamespace(grid=g, elevation=elev))
        want = caster.cast(o, d, RANGE_M, coherent=False)
        dt = time.perf_counter() - t
    finally:
        raw.unlink(missing_ok=True)
    same = _identical(want, got)
    print(
        f"whole DEM, in-memory RayCaster: {'bit-identical' if same else 'DIFFERENT'} "
        f"({dt:.2f} s, pyramid included; its peak RSS {_hwm_mb():.0f} MiB)"
    )
    return same
