"""Test oracles for geoid undulations: grids read with rasterio (GDAL), interpolated here.

Independent of PROJ (which :class:`~demtrack.core.geo.geoid.GeoidModel` evaluates grids
through): GDAL's GTX/GTiff drivers read the file and numpy interpolates bilinearly
between the grid's nodes. Also writers of small grids (a hand-made .gtx, a GeoTIFF).
"""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import rasterio
from rasterio.transform import from_origin

__all__ = ["EGM96_DEBIAN", "egm96_n", "rasterio_bilinear", "write_gtx", "write_linear_tif"]

#: Debian proj-data's EGM96 15' grid.
EGM96_DEBIAN = Path("/usr/share/proj/egm96_15.gtx")


def rasterio_bilinear(path: Path, lat_deg: np.ndarray, lon_deg: np.ndarray) -> np.ndarray:
    """Bilinear N between the grid's nodes, read with rasterio; longitudes wrap for global grids."""
    with rasterio.open(path) as ds:
        n = ds.read(1).astype(np.float64)
        t = ds.transform
    # Node (row i, column j) sits at the centre of GDAL's pixel (i, j).
    lon0, lat0, dlon, dlat = t.c + t.a / 2, t.f + t.e / 2, t.a, -t.e
    rows, cols = n.shape
    x = np.mod(np.asarray(lon_deg) - lon0, 360.0) / dlon  # .gtx may run 0..360 deg east
    y = (lat0 - np.asarray(lat_deg)) / dlat
    global_lon = abs(cols * dlon - 360.0) < 1e-9
    if global_lon:
        x = np.mod(x, cols)
    j = np.clip(np.floor(x).astype(int), 0, cols - 1 if global_lon else cols - 2)
    i = np.clip(np.floor(y).astype(int), 0, rows - 2)
    fx, fy = x - j, y - i
    j1 = (j + 1) % cols if global_lon else j + 1
    return (
        n[i, j] * (1 - fx) * (1 - fy)
        + n[i, j1] * fx * (1 - fy)
        + n[i + 1, j] * (1 - fx) * fy
        + n[i + 1, j1] * fx * fy
    )


def write_linear_tif(path: Path, a: float, b: float, c: float) -> None:
    """A national-geoid-like GeoTIFF: N = a + b * lon + c * lat on 0.05 deg nodes."""
    lon0, lat0, d = -80.0, 40.6, 0.05
    rows, cols = 9, 11
    lon = lon0 + d * np.arange(cols)
    lat = lat0 - d * np.arange(rows)
    n = (a + b * lon[None, :] + c * lat[:, None]).astype(np.float32)
    profile = dict(driver="GTiff", width=cols, height=rows, count=1, dtype="float32")
    tr = from_origin(lon0 - d / 2, lat0 + d / 2, d, d)
    with rasterio.open(path, "w", crs="EPSG:4326", transform=tr, **profile) as ds:
        ds.write(n, 1)


def write_gtx(path: Path, lat0: float, lon0: float, d: float, n: np.ndarray) -> None:
    """A .gtx written by hand: big-endian header, float32 rows from south to north."""
    rows, cols = n.shape
    head = struct.pack(">4d2i", lat0, lon0, d, d, rows, cols)
    path.write_bytes(head + n.astype(">f4").tobytes())


def egm96_n(lat_deg, lon_deg):
    """EGM96 N (m) from Debian's egm96_15.gtx read by rasterio, bilinear; None without it."""
    if not EGM96_DEBIAN.is_file():
        return None
    return rasterio_bilinear(EGM96_DEBIAN, np.asarray(lat_deg, float), np.asarray(lon_deg, float))
