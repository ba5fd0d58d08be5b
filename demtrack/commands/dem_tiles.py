"""``demtrack dem tile|synth``: a tiled DEM (a Cloud-Optimized GeoTIFF) with its block min/max.

``dem tile`` rewrites any north-up GeoTIFF DEM (a site's ``dem.tif`` included) window by
window; ``dem synth`` writes a smooth synthetic terrain of any size (40,000 x 40,000 cells
for the large-DEM benchmark), strip by strip. Both refuse to start when the disk cannot
hold the output. See ``docs/large-dems.md``.
"""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

from demtrack.core.errors import InputFileError

from .common import positive, positive_int, require_suffix

__all__ = ["register"]

#: Share of the raw float32 size writing a tiled DEM may take at its peak, for the free-disk
#: check: the streamed tiled file and the COG rewritten from it (with its overviews, and
#: GDAL's temporary overview file) exist together, each about 0.4 .. 0.7 of raw on smooth
#: terrain with the floating-point predictor.
_DISK_SHARE = 1.6


def _check_disk(out: Path, cells: int, bands: int) -> None:
    need = int(cells * 4 * bands * _DISK_SHARE)
    free = shutil.disk_usage(out.parent if out.parent.exists() else Path(".")).free
    if free < need:
        raise InputFileError(
            f"{out.parent}: {free / 1e9:.1f} GB free, the tiled DEM may need {need / 1e9:.1f} GB"
        )


def _check_tile(tile: int) -> None:
    if tile < 16 or tile > 4096 or tile & (tile - 1):
        raise InputFileError(f"--tile must be a power of two from 16 to 4096, got {tile}")


def _report(kind: str, out: Path, t0: float) -> None:
    from demtrack.core.terrain.tiled_dem import TiledDem

    td = TiledDem.open(out)
    g = td.grid
    size = out.stat().st_size
    print(
        f"{kind} {out}: {g.nrows} x {g.ncols} cells of {g.cell_m:g} m, tiles {td.tile}, "
        f"{size / 1e6:.1f} MB ({size / td.nbytes_cells:.0%} of float32), "
        f"z {td.z_min:.2f} .. {td.z_max:.2f} m, {time.perf_counter() - t0:.1f} s"
    )


def _run_tile(args: argparse.Namespace) -> int:
    import rasterio
    from rasterio.errors import RasterioError

    from demtrack.core.terrain.tiled_write import tile_geotiff

    require_suffix(args.output, (".tif", ".tiff"), "--output")
    _check_tile(args.tile)
    if not args.dem.is_file():
        raise InputFileError(f"DEM {args.dem} does not exist")
    try:
        with rasterio.open(args.dem) as src:
            cells, bands = src.width * src.height, 3 if src.count >= 3 else 1
    except RasterioError as exc:
        raise InputFileError(f"cannot read DEM {args.dem}: {exc}") from None
    if args.output.resolve() == args.dem.resolve():
        raise InputFileError("--output must not be the input DEM")
    _check_disk(args.output, cells, bands)
    t0 = time.perf_counter()
    tile_geotiff(args.dem, args.output, tile=args.tile, compress=args.compress)
    _report("tiled", args.output, t0)
    return 0


def _run_synth(args: argparse.Namespace) -> int:
    from demtrack.core.terrain.tiled_write import synth_tiled

    require_suffix(args.output, (".tif", ".tiff"), "--output")
    if args.size < 2:
        raise InputFileError(f"--size must be at least 2 cells, got {args.size}")
    _check_tile(args.tile)
    _check_disk(args.output, args.size * args.size, 1)
    t0 = time.perf_counter()
    print(f"writing {args.size} x {args.size} cells to {args.output} ...", file=sys.stderr)
    synth_tiled(
        args.output,
        args.size,
        cell_m=args.cell,
        seed=args.seed,
        tile=args.tile,
        compress=args.compress,
    )
    _report("synthetic", args.output, t0)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``dem`` command (``dem tile``, ``dem synth``)."""
    p = sub.add_parser("dem", help="tiled DEMs for sites larger than memory")
    dsub = p.add_subparsers(dest="dem_command", metavar="ACTION", required=True)

    def common(q: argparse.ArgumentParser) -> None:
        q.add_argument("-o", "--output", type=Path, required=True, metavar="OUT.tif")
        q.add_argument(
            "--tile",
            type=positive_int,
            default=512,
            help="internal tile side in cells, a power of two (default 512)",
        )
        q.add_argument(
            "--compress", choices=("deflate", "zstd"), default="deflate", help="default deflate"
        )

    t = dsub.add_parser(
        "tile", help="rewrite a GeoTIFF DEM as a tiled DEM (COG) with block min/max"
    )
    t.add_argument("--dem", type=Path, required=True, metavar="IN.tif")
    common(t)
    t.set_defaults(func=_run_tile)
    s = dsub.add_parser("synth", help="write a synthetic tiled DEM of SIZE x SIZE cells")
    s.add_argument("--size", type=positive_int, required=True, metavar="CELLS")
    s.add_argument("--cell", type=positive, default=1.0, help="cell size in m (default 1)")
    s.add_argument("--seed", type=int, default=0, help="terrain seed (default 0)")
    common(s)
    s.set_defaults(func=_run_synth)
