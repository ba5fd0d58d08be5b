"""Bring rasters and point clouds in any CRS into the site frame, and give the frame a CRS.

Every target cell centre ``(e, n)`` of a :class:`~demtrack.core.terrain.grid.GridSpec` in the local
frame is carried exactly to the source CRS (ENU -> WGS84 geodetic -> source CRS through
PROJ) and the source is sampled there, bilinearly between source cell *centres* (a source
value belongs to its cell centre: no half-cell shift). Meridian convergence, grid scale and
earth curvature are therefore all accounted for, not approximated: ignoring a 0.9 deg
convergence (UTM 17N at Bushy Run) would misplace terrain by ~5 m at 300 m from the anchor.

Heights: elevations are returned as local-frame ``Z`` (ENU up), which is not the
ellipsoidal height: the tangent plane leaves the ellipsoid by ~d^2 / 2R, about 7 mm at
300 m and 8 cm at 1 km from the anchor.
"""

from __future__ import annotations

from os import PathLike
from typing import Any, Literal

import numpy as np
from affine import Affine

from ..errors import CrsError, DemError, GeoidError, InputFileError
from ..geo.geodesy import (
    WGS84_A_M,
    WGS84_F,
    LocalFrame,
    as_crs,
    cached_transformer,
    horizontal_crs,
    z_unit_m_of,
)
from ..geo.geoid import GeoidModel, as_geoid
from .grid import GridSpec

__all__ = [
    "RESAMPLING_METHODS",
    "bilinear_at_centres",
    "image_to_rgba",
    "local_crs_wkt",
    "points_to_local",
    "read_raster_to_local",
    "resample_at_centres",
    "source_window",
    "unit_m_from_tag",
    "warp_to_local",
]

#: How a source raster is sampled at a target cell (see :func:`resample_at_centres`).
RESAMPLING_METHODS = ("bilinear", "cubic", "nearest", "average")

_CHUNK_CELLS = 262_144  # cells per batch: bounds the temporaries to a few tens of MB
_HULL_TOL_PX = 1e-6  # round-off allowance at the hull of source cell centres


# --------------------------------------------------------------------------- sampling


def _centre_index(
    col_c: Any, row_c: Any, nr: int, nc: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centre-index coordinates clipped to the hull of cell centres, and which are inside.

    The centre of cell (r, c) sits at (c, r); inside means within the tolerance.
    """
    gx = np.asarray(col_c, dtype=np.float64) - 0.5
    gy = np.asarray(row_c, dtype=np.float64) - 0.5
    inside = (
        (gx >= -_HULL_TOL_PX)
        & (gx <= nc - 1 + _HULL_TOL_PX)
        & (gy >= -_HULL_TOL_PX)
        & (gy <= nr - 1 + _HULL_TOL_PX)
    )
    gx = np.clip(np.where(inside, gx, 0.0), 0.0, nc - 1)
    gy = np.clip(np.where(inside, gy, 0.0), 0.0, nr - 1)
    return gx, gy, inside


def bilinear_at_centres(
    values: np.ndarray, transform: Affine, x: np.ndarray, y: np.ndarray
) -> np.ndarray:
    """Bilinear interpolation of cell-centre values at points ``(x, y)``.

    Parameters
    ----------
    values : ndarray, shape (rows, cols) or (bands, rows, cols)
        Source values, float with NaN = nodata.
    transform : Affine
        GDAL/rasterio affine of the source (maps pixel *corners*; any rotation allowed).
    x, y : ndarray
        Points in the source CRS units, same shape ``S``.

    Returns
    -------
    ndarray, shape S or (bands,) + S
        NaN outside the hull of cell centres or where any of the 4 surrounding centres
        is NaN (the conventions' hole rule).
    """
    v = values[None] if values.ndim == 2 else values
    nb, nr, nc = v.shape
    col_c, row_c = ~transform @ (np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    gx, gy, inside = _centre_index(col_c, row_c, nr, nc)
    c0 = np.minimum(np.floor(gx).astype(np.int64), max(nc - 2, 0))
    r0 = np.minimum(np.floor(gy).astype(np.int64), max(nr - 2, 0))
    c1 = np.minimum(c0 + 1, nc - 1)
    r1 = np.minimum(r0 + 1, nr - 1)
    fx = gx - c0
    fy = gy - r0
    out = np.empty((nb,) + gx.shape, dtype=np.float64)
    for b in range(nb):
        vb = v[b]
        top = vb[r0, c0] * (1.0 - fx) + vb[r0, c1] * fx
        bot = vb[r1, c0] * (1.0 - fx) + vb[r1, c1] * fx
        # A NaN corner poisons the patch even where its weight is 0 (hole rule);
        # multiplying by zero keeps NaN, so the rule holds by construction.
        out[b] = np.where(inside, top * (1.0 - fy) + bot * fy, np.nan)
    return out[0] if values.ndim == 2 else out


def _keys_cubic(t: np.ndarray) -> np.ndarray:
    """Keys' cubic convolution kernel (a = -0.5, GDAL's "cubic") at offsets ``t``."""
    a = -0.5
    t = np.abs(t)
    return np.where(
        t <= 1.0,
        (a + 2.0) * t**3 - (a + 3.0) * t**2 + 1.0,
        np.where(t < 2.0, a * t**3 - 5.0 * a * t**2 + 8.0 * a * t - 4.0 * a, 0.0),
    )


def resample_at_centres(
    values: np.ndarray,
    transform: Affine,
    x: np.ndarray,
    y: np.ndarray,
    method: str = "bilinear",
) -> np.ndarray:
    """Sample cell-centre values at points ``(x, y)`` by a stated method.

    Parameters
    ----------
    values, transform, x, y
        As :func:`bilinear_at_centres`.
    method : {"bilinear", "cubic", "nearest", "average"}
        ``bilinear``: :func:`bilinear_at_centres`. ``cubic``: Keys' cubic convolution
        (a = -0.5, GDAL's "cubic") over the 4 x 4 centres around the point, edge centres
        repeated beyond the raster; interpolating (it passes through the centre values)
        and exact on quadratic surfaces. ``nearest``: the value of the cell containing the
        point (defined over the whole raster, not only the hull of centres).
        ``average`` samples bilinearly here; :func:`warp_to_local` averages over the
        target cell.

    Returns
    -------
    ndarray
        NaN outside the domain or where a value the method uses is NaN.
    """
    if method in ("bilinear", "average"):
        return bilinear_at_centres(values, transform, x, y)
    if method not in RESAMPLING_METHODS:
        raise DemError(f"resampling must be one of {', '.join(RESAMPLING_METHODS)}; got {method!r}")
    v = values[None] if values.ndim == 2 else values
    nb, nr, nc = v.shape
    col_c, row_c = ~transform @ (np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64))
    col_c, row_c = np.asarray(col_c), np.asarray(row_c)
    out = np.empty((nb,) + col_c.shape, dtype=np.float64)
    if method == "nearest":
        inside = (col_c >= 0) & (col_c < nc) & (row_c >= 0) & (row_c < nr)
        c = np.clip(np.floor(np.where(inside, col_c, 0.0)).astype(np.int64), 0, nc - 1)
        r = np.clip(np.floor(np.where(inside, row_c, 0.0)).astype(np.int64), 0, nr - 1)
        for b in range(nb):
            out[b] = np.where(inside, v[b][r, c], np.nan)
        return out[0] if values.ndim == 2 else out
    gx, gy, inside = _centre_index(col_c, row_c, nr, nc)
    c1 = np.floor(gx).astype(np.int64)
    r1 = np.floor(gy).astype(np.int64)
    fx, fy = gx - c1, gy - r1
    for b in range(nb):
        acc = np.zeros(gx.shape)
        for i in range(-1, 3):
            wy = _keys_cubic(fy - i)
            rr = np.clip(r1 + i, 0, nr - 1)
            for j in range(-1, 3):
                cc = np.clip(c1 + j, 0, nc - 1)
                acc = acc + wy * _keys_cubic(fx - j) * v[b][rr, cc]
        out[b] = np.where(inside, acc, np.nan)
    return out[0] if values.ndim == 2 else out


def _as_float_source(src_array: Any, src_nodata: float | None) -> np.ndarray:
    if isinstance(src_array, np.ma.MaskedArray):
        data = np.ma.getdata(src_array).astype(np.float64)
        data[np.ma.getmaskarray(src_array)] = np.nan
    else:
        data = np.asarray(src_array).astype(np.float64)
    if src_nodata is not None:
        nd = float(src_nodata)
        data[data == nd if np.isfinite(nd) else np.isnan(data)] = np.nan
    data[~np.isfinite(data)] = np.nan
    return data


# --------------------------------------------------------------------------- warping


def warp_to_local(
    src_array: Any,
    src_transform: Affine,
    src_crs: Any,
    frame: LocalFrame,
    grid: GridSpec,
    *,
    kind: Literal["elevation", "image"] = "elevation",
    src_nodata: float | None = None,
    geoid_undulation_m: float | GeoidModel = 0.0,
    z_unit_m: float | None = None,
    z_local: Any = 0.0,
    max_iter: int = 6,
    tol_m: float = 1e-6,
    resampling: str = "bilinear",
) -> np.ndarray:
    """Resample a georeferenced raster onto a grid of the local frame.

    Parameters
    ----------
    src_array : ndarray or masked array
        ``(rows, cols)`` elevations (``kind="elevation"``) or ``(bands, rows, cols)`` /
        ``(rows, cols)`` image values (``kind="image"``, e.g. uint8 RGB), rasterio order.
        Masked cells are nodata.
    src_transform : Affine
        Source GDAL affine (pixel corners).
    src_crs : CRS-like
        Source CRS: projected (any linear unit), geographic (degrees) or compound.
    frame : LocalFrame
        The site frame.
    grid : GridSpec
        Target grid, coordinates ``(e, n)`` in metres of the local frame.
    kind : {"elevation", "image"}
    src_nodata : float, optional
        Source value meaning "no data" (per band for images).
    geoid_undulation_m : float or GeoidModel
        The geoid of orthometric source heights: ``h = H * z_unit_m + N(lat, lon)``, ``N``
        evaluated at each cell's position (a :class:`~demtrack.core.geo.geoid.GeoidModel`,
        e.g. EGM96), or one constant ``N`` (m). 0 (or an ellipsoidal model) means the
        source heights are ellipsoidal (WGS84).
    z_unit_m : float, optional
        Metres per source height unit; default from the CRS (see
        :func:`~demtrack.core.geo.geodesy.z_unit_m_of`: ftUS for a ftUS state plane).
    z_local : float or ndarray (nrows, ncols)
        Images only: local Z (m) of the surface each target cell shows (e.g. the warped
        DEM). Using 0 instead of the true height moves the sample by ``dz * d / R``
        (1.6 cm for 100 m of relief at 1 km): negligible for an orthophoto.
    max_iter, tol_m : int, float
        Elevations only: height iteration limit and convergence threshold (m).
    resampling : {"bilinear", "cubic", "nearest", "average"}
        Elevations only: how the source is sampled (:func:`resample_at_centres`).
        ``average``: the mean of ``k x k`` bilinear samples spread evenly over the target
        cell (``k`` = target cell / source pixel, rounded up), at the height the centre
        solved for; NaN if any is NaN. For downsampling (a target cell larger than the
        source's pixels).

    Returns
    -------
    ndarray
        ``kind="elevation"``: float32 ``(nrows, ncols)`` local-frame Z (m, ENU up).
        ``kind="image"``: float32 ``(bands, nrows, ncols)`` bilinear band values
        (``(nrows, ncols)`` for a 2-D source).
        NaN outside the source's hull of cell centres and at source nodata.

    Notes
    -----
    The ellipsoidal height of the terrain at a target cell is unknown until the source is
    sampled, and the point sampled depends (slightly) on it because the local vertical
    through ``(e, n)`` is tilted by ``d / R`` against the ellipsoid normal there. So
    elevations iterate along that vertical: start at ``u = 0``, sample ``H`` at the
    point's horizontal position, set ``u += (h_sampled - h_point) / cos(tilt)``, repeat.
    Each step shrinks the error by a factor ``slope * d / R`` (1.6e-4 per unit slope at
    1 km), so it converges in 2-3 iterations. Measured (tests' UTM 17N case: a terrain
    spanning 630 m of height, slopes to 0.3, cells to 1.4 km from the anchor), the residual
    ``max |h_point - h_sampled|`` is 1.6 cm after one update, 8e-7 m after two and 5e-9 m
    after three. Iteration stops when every cell's update is below ``tol_m``; the float32
    output then rounds to ~1e-5 m.
    """
    if kind not in ("elevation", "image"):
        raise DemError(f"kind must be 'elevation' or 'image'; got {kind!r}")
    if resampling not in RESAMPLING_METHODS:
        raise DemError(
            f"resampling must be one of {', '.join(RESAMPLING_METHODS)}; got {resampling!r}"
        )
    if not isinstance(frame, LocalFrame):
        raise CrsError("frame must be a LocalFrame")
    if not isinstance(grid, GridSpec):
        raise DemError("grid must be a GridSpec")
    transform = src_transform if isinstance(src_transform, Affine) else Affine(*src_transform)
    if abs(transform.determinant) == 0.0:
        raise DemError("source transform is singular")
    src = _as_float_source(src_array, src_nodata)
    if kind == "elevation" and src.ndim != 2:
        raise DemError(f"an elevation source must be 2-D; got shape {src.shape}")
    if src.ndim not in (2, 3) or min(src.shape) < 1:
        raise DemError(
            f"source raster must be (rows, cols) or (bands, rows, cols); got shape {src.shape}"
        )
    if src_crs is None:
        raise CrsError("source raster has no CRS; cannot place it in the site frame")
    hcrs = horizontal_crs(src_crs)
    project = _projector(hcrs, transform, src.shape[-2:])
    k = z_unit_m_of(src_crs) if z_unit_m is None else float(z_unit_m)
    if not (np.isfinite(k) and k > 0):
        raise DemError(f"z_unit_m must be positive; got {z_unit_m}")
    try:
        n_geoid = as_geoid(geoid_undulation_m)
    except GeoidError as exc:
        raise DemError(f"geoid_undulation_m: {exc}") from None

    e_all, n_all = grid.centres()
    rows_per_chunk = max(1, _CHUNK_CELLS // grid.ncols)
    if kind == "elevation":
        out = np.full(grid.shape, np.nan, dtype=np.float32)
    else:
        nb = 1 if src.ndim == 2 else src.shape[0]
        out = np.full((nb,) + grid.shape, np.nan, dtype=np.float32)
        zl = np.broadcast_to(np.asarray(z_local, dtype=np.float64), grid.shape)
        if not np.all(np.isfinite(zl)):
            raise DemError("z_local must be finite")

    for r0 in range(0, grid.nrows, rows_per_chunk):
        sl = slice(r0, min(grid.nrows, r0 + rows_per_chunk))
        e, n = e_all[sl], n_all[sl]
        if kind == "image":
            lat, lon, _ = frame.to_geodetic(e, n, zl[sl])
            x, y = project(lon, lat)
            vals = bilinear_at_centres(src, transform, np.asarray(x), np.asarray(y))
            out[:, sl] = vals if vals.ndim == 3 else vals[None]
            continue
        u, ok = _solve_heights(
            src, transform, project, frame, e, n, k, n_geoid, max_iter, tol_m, resampling
        )
        if resampling == "average":
            u, ok = _average_heights(src, transform, project, frame, grid, e, n, u, ok, k, n_geoid)
        out[sl] = np.where(ok, u, np.nan)
    return out if kind == "elevation" or src.ndim == 3 else out[0]


def _projector(hcrs: Any, transform: Affine, shape: tuple[int, ...]) -> Any:
    """``(lon, lat) -> (x, y)`` in the source CRS, as float64 arrays.

    For a geographic source, longitudes are wrapped to within 180 deg of the raster's
    centre, so a raster stored as 179.9 .. 180.1 (or -180.1 .. -179.9) is found from
    either side of the antimeridian.
    """
    to_src = cached_transformer("EPSG:4326", hcrs.to_wkt())
    x_mid = (transform @ (shape[-1] / 2.0, shape[-2] / 2.0))[0] if hcrs.is_geographic else None

    def project(lon: np.ndarray, lat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        x, y = to_src.transform(lon, lat)
        x, y = np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        if x_mid is not None:
            x = x_mid + (x - x_mid + 180.0) % 360.0 - 180.0
        return x, y

    return project


def _solve_heights(
    src: np.ndarray,
    transform: Affine,
    project: Any,
    frame: LocalFrame,
    e: np.ndarray,
    n: np.ndarray,
    k: float,
    n_geoid: GeoidModel,
    max_iter: int,
    tol_m: float,
    resampling: str = "bilinear",
) -> tuple[np.ndarray, np.ndarray]:
    """Fixed-point iteration along each cell's local vertical; see :func:`warp_to_local`."""
    up0 = frame.R_enu_ecef[2]
    u = np.zeros_like(e)
    ok = np.zeros(e.shape, dtype=bool)
    for _ in range(max(1, int(max_iter))):
        lat, lon, h = frame.to_geodetic(e, n, u)
        x, y = project(lon, lat)
        h_src = resample_at_centres(src, transform, x, y, resampling) * k + n_geoid.undulation_m(
            lat, lon
        )
        ok = np.isfinite(h_src)
        phi, lam = np.radians(lat), np.radians(lon)
        # cos of the angle between the frame's up and the ellipsoid normal at the point:
        # the rate at which h grows along the local vertical.
        cos_tilt = (
            up0[0] * np.cos(phi) * np.cos(lam)
            + up0[1] * np.cos(phi) * np.sin(lam)
            + up0[2] * np.sin(phi)
        )
        du = np.where(ok, (h_src - h) / cos_tilt, 0.0)
        u = u + du
        if not np.any(np.abs(du) > tol_m):
            break
    return u, ok


def _average_heights(
    src: np.ndarray,
    transform: Affine,
    project: Any,
    frame: LocalFrame,
    grid: GridSpec,
    e: np.ndarray,
    n: np.ndarray,
    u: np.ndarray,
    ok: np.ndarray,
    k: float,
    n_geoid: GeoidModel,
) -> tuple[np.ndarray, np.ndarray]:
    """Mean source height over each target cell (``resampling="average"``)."""
    # Source pixels per metre along E at the chunk's middle: sets the sub-sample count.
    e_mid, n_mid = float(np.mean(e)), float(np.mean(n))
    lat, lon, _ = frame.to_geodetic(np.array([e_mid, e_mid + 1.0]), np.array([n_mid, n_mid]), 0.0)
    x, y = project(lon, lat)
    col, row = ~transform @ (x, y)
    px_per_m = float(np.hypot(col[1] - col[0], row[1] - row[0]))
    m = max(1, int(np.ceil(grid.cell_m * px_per_m - 1e-9)))
    offs = ((np.arange(m) + 0.5) / m - 0.5) * grid.cell_m
    total = np.zeros_like(u)
    good = ok.copy()
    u0 = np.where(ok, u, 0.0)
    for de in offs:
        for dn in offs:
            lat, lon, h = frame.to_geodetic(e + de, n + dn, u0)
            x, y = project(lon, lat)
            h_src = bilinear_at_centres(src, transform, x, y) * k + n_geoid.undulation_m(lat, lon)
            good &= np.isfinite(h_src)
            # the sample's height above the local vertical's point, as local Z
            total = total + np.where(np.isfinite(h_src), u0 + (h_src - h), 0.0)
    return total / (m * m), good


def points_to_local(
    x: Any,
    y: Any,
    z: Any,
    crs: Any,
    frame: LocalFrame,
    *,
    geoid_undulation_m: float | GeoidModel = 0.0,
    z_unit_m: float | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Point cloud (e.g. lidar in UTM) to local ``(e, n, u)`` arrays (m).

    Exact per point; see :meth:`~demtrack.core.geo.geodesy.LocalFrame.to_enu_from_crs` for
    the height rules (``h = z * z_unit_m + N``). ``geoid_undulation_m`` is a constant
    ``N`` (m) or a :class:`~demtrack.core.geo.geoid.GeoidModel` evaluated at each point.
    """
    if crs is None:
        raise CrsError("point cloud has no CRS; cannot place it in the site frame")
    if isinstance(geoid_undulation_m, GeoidModel) and geoid_undulation_m.kind == "grid":
        # N per point: at the points' own lon/lat (it depends on the horizontal only).
        hcrs = horizontal_crs(crs)
        lon, lat = cached_transformer(hcrs.to_wkt(), "EPSG:4326").transform(
            np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)
        )
        k = z_unit_m_of(crs) if z_unit_m is None else float(z_unit_m)
        h = np.asarray(z, dtype=np.float64) * k + geoid_undulation_m.undulation_m(lat, lon)
        e, n, u = frame.to_enu_from_crs(x, y, h, crs, z_unit_m=1.0)
    else:
        n_const = as_geoid(geoid_undulation_m).n_m
        e, n, u = frame.to_enu_from_crs(x, y, z, crs, geoid_undulation_m=n_const, z_unit_m=z_unit_m)
    return np.asarray(e), np.asarray(n), np.asarray(u)


# --------------------------------------------------------------------------- files

_UNIT_M = {
    "m": 1.0,
    "metre": 1.0,
    "meter": 1.0,
    "metres": 1.0,
    "meters": 1.0,
    "ft": 0.3048,
    "foot": 0.3048,
    "feet": 0.3048,
    "international foot": 0.3048,
    "us-ft": 1200.0 / 3937.0,
    "ftus": 1200.0 / 3937.0,
    "us survey foot": 1200.0 / 3937.0,
    "foot_us": 1200.0 / 3937.0,
    "us_survey_foot": 1200.0 / 3937.0,
}


def unit_m_from_tag(tag: str | None) -> float | None:
    """Metres per unit for a GDAL band unit tag ("metre", "US survey foot", ...).

    None for an empty or unknown tag (the caller then falls back on the CRS).
    """
    return _UNIT_M.get((tag or "").strip().lower())


def read_raster_to_local(
    path: str | PathLike[str],
    frame: LocalFrame,
    grid: GridSpec,
    *,
    kind: Literal["elevation", "image"] = "elevation",
    bands: tuple[int, ...] | None = None,
    geoid_undulation_m: float | GeoidModel = 0.0,
    z_unit_m: float | None = None,
    z_local: Any = 0.0,
) -> np.ndarray:
    """Read a GeoTIFF (or any GDAL raster) and warp it onto ``grid``.

    Only the window of the source covering the grid (plus a 2-pixel margin) is read.
    Nodata, internal masks and alpha bands become NaN. The height unit comes from
    ``z_unit_m``, else the band's unit tag ("metre", "US survey foot", ...), else the CRS
    (see :func:`warp_to_local`). Images read bands 1-3 when there are at least three.

    Raises
    ------
    InputFileError
        If the file cannot be opened.
    CrsError
        If the raster has no CRS.
    """
    import rasterio  # heavy GDAL import only when files are read
    from rasterio.errors import RasterioIOError
    from rasterio.windows import Window

    try:
        ds = rasterio.open(path)
    except RasterioIOError as exc:
        raise InputFileError(f"cannot read raster {path}: {str(exc).splitlines()[0]}") from exc
    with ds:
        if ds.crs is None:
            raise CrsError(
                f"raster {path} has no CRS; reproject or tag it (e.g. gdal_edit.py "
                "-a_srs) before importing"
            )
        src_crs = as_crs(ds.crs.to_wkt())
        if bands is None:
            bands = (1,) if kind == "elevation" else tuple(range(1, min(ds.count, 3) + 1))
        if kind == "elevation" and len(bands) != 1:
            raise DemError("an elevation raster is read from exactly one band")
        if z_unit_m is None and kind == "elevation":
            z_unit_m = unit_m_from_tag(ds.units[bands[0] - 1])
        c0, r0, c1, r1 = source_window(ds.transform, (ds.height, ds.width), src_crs, frame, grid)
        c0, r0 = max(c0, 0), max(r0, 0)
        c1, r1 = min(c1, ds.width), min(r1, ds.height)
        if c1 <= c0 or r1 <= r0:
            shape = grid.shape if kind == "elevation" else (len(bands),) + grid.shape
            return np.full(shape, np.nan, dtype=np.float32)
        window = Window(c0, r0, c1 - c0, r1 - r0)
        data = ds.read(list(bands), window=window, masked=True)
        w_transform = ds.window_transform(window)
    src = data[0] if kind == "elevation" else data
    return warp_to_local(
        src,
        w_transform,
        src_crs,
        frame,
        grid,
        kind=kind,
        geoid_undulation_m=geoid_undulation_m,
        z_unit_m=z_unit_m,
        z_local=z_local,
    )


def source_window(
    transform: Affine, shape: tuple[int, int], src_crs: Any, frame: LocalFrame, grid: GridSpec
) -> tuple[int, int, int, int]:
    """Pixel bounds ``(c0, r0, c1, r1)`` (exclusive ends) covering the grid's outline.

    Parameters
    ----------
    transform : Affine
        Source affine (pixel corners).
    shape : (rows, cols)
        Source shape (geographic sources wrap longitudes around its centre).
    src_crs : CRS-like
    frame : LocalFrame
    grid : GridSpec
        Target grid in the local frame.

    Returns
    -------
    (c0, r0, c1, r1) : int
        Unclipped pixel window with a 2-pixel margin; may lie partly or wholly outside
        the source.
    """
    # The ENU -> source map is a smooth bijection, so the image of the grid's outline
    # bounds the image of the whole grid.
    t = np.linspace(0.0, 1.0, 65)
    x0, y0, x1, y1 = grid.bounds
    e = np.concatenate(
        [x0 + (x1 - x0) * t, np.full_like(t, x1), x1 - (x1 - x0) * t, np.full_like(t, x0)]
    )
    n = np.concatenate(
        [np.full_like(t, y0), y0 + (y1 - y0) * t, np.full_like(t, y1), y1 - (y1 - y0) * t]
    )
    lat, lon, _ = frame.to_geodetic(e, n, 0.0)
    x, y = _projector(horizontal_crs(src_crs), transform, shape)(lon, lat)
    col, row = ~transform @ (x, y)
    margin = 2
    return (
        int(np.floor(np.min(col))) - margin,
        int(np.floor(np.min(row))) - margin,
        int(np.ceil(np.max(col))) + margin,
        int(np.ceil(np.max(row))) + margin,
    )


# --------------------------------------------------------------------------- output


def image_to_rgba(warped: np.ndarray) -> np.ndarray:
    """``(bands, nrows, ncols)`` float image with NaN holes to ``(nrows, ncols, 4)`` uint8.

    Bands 1-3 become RGB (one band is repeated as grey); alpha is 0 where any band is
    NaN, else 255. Values are rounded and clipped to [0, 255].
    """
    w = np.asarray(warped, dtype=np.float64)
    if w.ndim == 2:
        w = w[None]
    if w.ndim != 3 or w.shape[0] < 1:
        raise DemError(f"expected a (bands, rows, cols) image; got shape {w.shape}")
    rgb = np.repeat(w[:1], 3, axis=0) if w.shape[0] < 3 else w[:3]
    valid = np.all(np.isfinite(rgb), axis=0)
    out = np.zeros(rgb.shape[1:] + (4,), dtype=np.uint8)
    out[..., :3] = np.clip(np.rint(np.nan_to_num(np.moveaxis(rgb, 0, -1))), 0, 255)
    out[..., 3] = np.where(valid, 255, 0)
    out[~valid, :3] = 0
    return out


def local_crs_wkt(frame: LocalFrame, *, surface_h_m: float | None = None) -> str:
    """WKT2 of a 2-D projected CRS whose x/y are the local frame's e/n on the ground.

    For georeferencing site rasters (GeoTIFF) in GIS. ``+proj=topocentric`` is a 3-D
    conversion of geocentric coordinates, not a 2-D map projection, so it cannot serve.
    This is PROJ's ellipsoidal Orthographic projection (EPSG method 9840) centred on the
    anchor. On an ellipsoid it maps a point to exactly the ``(e, n)`` of its foot on that
    ellipsoid; for a point ``dz`` above the ellipsoid, x/y differ from ENU by
    ``dz * d / R`` towards the origin (d = distance from the anchor).

    So the ellipsoid is WGS84 raised by ``surface_h_m`` (a + h, b + h; default the
    anchor's height): measured at Bushy Run (h0 = 300 m) within 2.8 km of the anchor,
    x/y equal ENU e/n to 1e-6 m at h = h0 and within 4.3 cm for h = h0 +- 100 m. With
    ``surface_h_m=0`` the CRS is a plain WGS84 orthographic one (a recognised datum),
    off by 13 cm at 2.8 km for terrain at 300 m. GIS software relates the raised datum to
    WGS84 with a "ballpark" (identity) latitude/longitude offset, which is exactly what
    is wanted: WGS84 geodetic coordinates pass through unchanged.
    """
    h = frame.h_m if surface_h_m is None else float(surface_h_m)
    if not np.isfinite(h):
        raise CrsError("surface_h_m must be finite")
    lat0, lon0 = frame.lat_deg, ((frame.lon_deg + 180.0) % 360.0) - 180.0
    if h == 0.0:
        geog = (
            'BASEGEOGCRS["WGS 84",DATUM["World Geodetic System 1984",'
            'ELLIPSOID["WGS 84",6378137,298.257223563,LENGTHUNIT["metre",1]]],'
            'PRIMEM["Greenwich",0,ANGLEUNIT["degree",0.0174532925199433]]]'
        )
    else:
        a = WGS84_A_M + h
        b = WGS84_A_M * (1.0 - WGS84_F) + h
        rf = a / (a - b)
        tag = f"WGS 84 raised by {h:.3f} m"
        geog = (
            f'BASEGEOGCRS["{tag}",DATUM["{tag}",'
            f'ELLIPSOID["{tag}",{a!r},{rf!r},LENGTHUNIT["metre",1]]],'
            'PRIMEM["Greenwich",0,ANGLEUNIT["degree",0.0174532925199433]]]'
        )
    name = (
        f"demtrack local frame at {frame.lat_deg:.8f}, {frame.lon_deg:.8f}, "
        f"h {frame.h_m:.3f} m (orthographic, surface h {h:.3f} m)"
    )
    wkt = (
        f'PROJCRS["{name}",{geog},'
        'CONVERSION["demtrack site orthographic",METHOD["Orthographic",ID["EPSG",9840]],'
        f'PARAMETER["Latitude of natural origin",{lat0!r},'
        'ANGLEUNIT["degree",0.0174532925199433],ID["EPSG",8801]],'
        f'PARAMETER["Longitude of natural origin",{lon0!r},'
        'ANGLEUNIT["degree",0.0174532925199433],ID["EPSG",8802]],'
        'PARAMETER["False easting",0,LENGTHUNIT["metre",1],ID["EPSG",8806]],'
        'PARAMETER["False northing",0,LENGTHUNIT["metre",1],ID["EPSG",8807]]],'
        'CS[Cartesian,2],AXIS["easting (E)",east,ORDER[1],LENGTHUNIT["metre",1]],'
        'AXIS["northing (N)",north,ORDER[2],LENGTHUNIT["metre",1]]]'
    )
    as_crs(wkt)  # fail here, not in a GIS, if PROJ would reject it
    return wkt
