"""Benchmark: demtrack's viewsheds (fast sweep and exact) against GDAL's ``gdal_viewshed``.

All get the same DEM GeoTIFF (the ray-casting benchmark's synthetic terrain of hills,
buildings and trees) and the same observer; all are timed as whole processes (start-up,
reading the DEM, computing, writing the result). The reference verdict is one exact sight
line per cell on the bilinear surface (``method="exact"``: demtrack's ray caster from the
observer to the cell centre at ``elevation + target height``), itself checked against an
independent dense sampling of a random subset of the sight lines. GDAL's algorithm is an
approximation (it interpolates each cell's horizon from already-processed neighbours);
demtrack's default ``method="sweep"`` does the same, then re-checks with exact sight lines
wherever that interpolation could have changed the verdict. The start-up floor is a
process that imports everything and runs the kernels on a 4 x 4 DEM.

Usage: ``demtrack bench viewshed [--size 2000] [--observer-height 10] [--target-height 1.7]``.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.terrain.dem import Dem

from .synthetic_terrain import synthetic_dem

__all__ = ["main", "startup_floor", "viewshed_file"]

_TARGET_RIGHT = 0.999


def viewshed_file(
    dem_path: str,
    out_path: str,
    ox: float,
    oy: float,
    oz: float,
    tz: float,
    md: float,
    method: str = "sweep",
) -> None:
    """Whole-process job: read a DEM GeoTIFF, write its 0/255 viewshed GeoTIFF."""
    import rasterio

    from demtrack.core.visibility.viewshed import PanTiltLimits, viewshed

    dem = Dem.read(dem_path)
    t0 = time.perf_counter()
    z0 = float(dem.sample(np.array([ox]), np.array([oy]))[0])
    cam = observer_camera(ox, oy, z0 + oz)
    seen = viewshed(
        dem, cam, mode="reachable", target_height_m=tz, max_range_m=md,
        limits=PanTiltLimits(tilt_min_deg=-90.0, tilt_max_deg=90.0), method=method,
    )  # fmt: skip
    print(f"compute {time.perf_counter() - t0:.3f}")
    g = dem.grid
    with rasterio.open(
        out_path, "w", driver="GTiff", height=g.nrows, width=g.ncols, count=1, dtype="uint8",
        transform=g.transform,
    ) as dst:  # fmt: skip
        dst.write(np.where(seen, 255, 0).astype(np.uint8), 1)


def startup_floor() -> None:
    """Whole-process floor: the imports and kernels of :func:`viewshed_file`, a 4 x 4 DEM."""
    import rasterio  # noqa: F401

    from demtrack.core.terrain.grid import GridSpec
    from demtrack.core.visibility.viewshed import viewshed

    dem = Dem(GridSpec(0.0, 4.0, 1.0, 4, 4), np.zeros((4, 4), np.float32))
    viewshed(dem, observer_camera(2.0, 2.0, 3.0), mode="reachable")
    print("compute 0")


def observer_camera(x: float, y: float, z: float) -> Camera:
    """A camera at the observer; in ``reachable`` mode only its position matters."""
    return Camera.from_azimuth_tilt_roll(
        Intrinsics(100.0, 100.0, 99.5, 99.5, 200, 200), [x, y, z], 0.0, 0.0, 0.0
    )


def _timed(cmd: list[str]) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, check=True, capture_output=True, text=True)
    return time.perf_counter() - t0, proc.stdout


def _dense_check(dem: Dem, c: np.ndarray, tz: float, cells: np.ndarray) -> np.ndarray:
    """Independent verdicts: sample each sight line every 5 cm against ``Dem.sample``."""
    x, y = dem.grid.centres()
    out = np.zeros(len(cells), bool)
    for k, (r, q) in enumerate(cells):
        p = np.array([x[r, q], y[r, q], dem.elevation[r, q] + tz])
        dist = float(np.linalg.norm(p - c))
        t = np.linspace(0.0, 1.0, max(int(dist / 0.05), 10))
        t = t[t < 1 - 1e-3 - 0.05 / dist]
        line = c + t[:, None] * (p - c)
        out[k] = bool(np.all(line[:, 2] > dem.sample(line[:, 0], line[:, 1])))
    return out


def main(argv: list[str] | None = None) -> int:
    """Run the comparison and print the table; returns the exit status."""
    p = argparse.ArgumentParser(prog="demtrack bench viewshed", description=__doc__.split("\n")[0])
    p.add_argument("--size", type=int, default=2000, help="DEM rows = columns (default 2000)")
    p.add_argument("--observer-height", type=float, default=10.0, help="m above the DEM")
    p.add_argument("--target-height", type=float, default=1.7, help="m above the DEM")
    p.add_argument("--check", type=int, default=2000, help="sight lines checked densely")
    args = p.parse_args(argv)
    gdal = shutil.which("gdal_viewshed")
    syn = synthetic_dem(args.size)
    dem = Dem(syn.grid, syn.elevation)
    g = dem.grid
    ox, oy = g.x_min + 0.37 * g.ncols * g.cell_m, g.y_max - 0.41 * g.nrows * g.cell_m
    md = 2.0 * g.ncols * g.cell_m
    with tempfile.TemporaryDirectory() as tmp:
        dem_path, ours_path, gdal_path = (str(Path(tmp) / n) for n in ("d.tif", "o.tif", "g.tif"))
        # GDAL reads band 1; a plain single-band file keeps the comparison fair.
        import rasterio

        with rasterio.open(dem_path, "w", driver="GTiff", height=g.nrows, width=g.ncols,
                           count=1, dtype="float32", transform=g.transform) as dst:  # fmt: skip
            dst.write(dem.elevation, 1)

        def job(method: str) -> list[str]:
            code = (
                "from demtrack.bench.viewshed import viewshed_file; "
                f"viewshed_file({dem_path!r}, {ours_path!r}, {ox}, {oy}, "
                f"{args.observer_height}, {args.target_height}, {md}, {method!r})"
            )
            return [sys.executable, "-c", code]

        floor_job = "from demtrack.bench.viewshed import startup_floor; startup_floor()"
        t_floor, _ = _timed([sys.executable, "-c", floor_job])
        t_exact, out = _timed(job("exact"))
        t_exact_compute = float(out.split()[-1])
        with rasterio.open(ours_path) as src:
            exact = src.read(1) == 255
        t_ours, out = _timed(job("sweep"))
        t_compute = float(out.split()[-1])
        with rasterio.open(ours_path) as src:
            ours = src.read(1) == 255
        t_gdal = float("nan")
        theirs = None
        if gdal:
            t_gdal, _ = _timed([gdal, "-q", "-ox", str(ox), "-oy", str(oy),
                             "-oz", str(args.observer_height), "-tz", str(args.target_height),
                             "-md", str(md), "-cc", "1.0", dem_path, gdal_path])  # fmt: skip
            with rasterio.open(gdal_path) as src:
                theirs = src.read(1) == 255
    # The reference is the exact sight line per cell; check that claim independently on
    # a random subset.
    rng = np.random.default_rng(0)
    cells = np.column_stack(
        [rng.integers(0, g.nrows, args.check), rng.integers(0, g.ncols, args.check)]
    )
    z0 = float(dem.sample(np.array([ox]), np.array([oy]))[0]) + args.observer_height
    dense = _dense_check(dem, np.array([ox, oy, z0]), args.target_height, cells)
    agree_dense = float(np.mean(exact[cells[:, 0], cells[:, 1]] == dense))
    right = float(np.mean(ours == exact))
    print(
        f"viewshed of a {g.ncols} x {g.nrows} DEM ({g.cell_m} m cells), observer "
        f"{args.observer_height:g} m, target {args.target_height:g} m above the surface"
    )
    print(
        f"  exact (reference): {100 * exact.mean():5.1f} % visible, whole process "
        f"{t_exact:.2f} s, compute {t_exact_compute:.2f} s; agrees with dense sampling on "
        f"{100 * agree_dense:.2f} % of {args.check} lines"
    )
    print(
        f"  demtrack sweep:    {100 * ours.mean():5.1f} % visible, whole process {t_ours:.2f} s, "
        f"compute {t_compute:.3f} s; right on {100 * right:.3f} % of cells "
        f"({int(np.sum(ours != exact))} wrong)"
    )
    print(f"  start-up floor (imports + cached kernels, 4 x 4 DEM): {t_floor:.2f} s")
    if theirs is not None:
        right_gdal = float(np.mean(theirs == exact))
        print(
            f"  GDAL:              {100 * theirs.mean():5.1f} % visible, whole process "
            f"{t_gdal:.2f} s; right on {100 * right_gdal:.3f} % of cells"
        )
        flag = lambda r: "met" if r >= _TARGET_RIGHT else "missed"  # noqa: E731
        print(
            f"  target >= {100 * _TARGET_RIGHT:g} % right: sweep {flag(right)}, GDAL "
            f"{flag(right_gdal)}; whole process sweep / GDAL = {t_ours / t_gdal:.1f}x, "
            f"(sweep - floor) / GDAL = {(t_ours - t_floor) / t_gdal:.1f}x, "
            f"sweep / exact = {t_ours / t_exact:.2f}x"
        )
    else:
        print("  gdal_viewshed not found (Debian: apt-get install gdal-bin); GDAL skipped")
    return 0


if __name__ == "__main__":
    sys.exit(main())
