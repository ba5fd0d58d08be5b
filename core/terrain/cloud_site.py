"""A new site's terrain from a point cloud alone: CRS and units, anchor, surface, grid.

A LAS/LAZ tile in any CRS (projected in metres, international or US survey feet, or
geographic) is placed in a local frame anchored at the cloud's centre, on the ground,
with a WGS84 ellipsoidal height, then gridded into the site DEM (per-cell statistics,
a TIN between the points; :mod:`.tin`).

Heights: the file's z is in the CRS's vertical unit, else its horizontal linear unit (LAS
practice: a state plane in feet carries heights in feet), unless stated. Orthometric
heights ``H`` become ellipsoidal as ``h = H * z_unit_m + N`` with the site's geoid
undulation ``N``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..errors import CrsError, InputFileError
from ..geo.geodesy import LocalFrame, as_crs, cached_transformer, horizontal_crs, z_unit_m_of
from ..geo.geoid import GeoidModel, as_geoid
from .pointcloud import GROUND_CLASS, PointCloud

__all__ = [
    "CloudCrs",
    "anchor_for_cloud",
    "cloud_crs",
    "select_surface",
]

#: Points around the centre whose median height is the anchor's height.
_ANCHOR_POINTS = 25


@dataclass(frozen=True)
class CloudCrs:
    """The CRS of a point cloud and the size of its units.

    Attributes
    ----------
    crs_wkt : str
        The CRS (WKT) the x, y, z are in.
    name : str
        Its name.
    xy_unit : str
        Name of the horizontal unit ("metre", "foot", "US survey foot", "degree").
    xy_unit_m : float
        Metres per horizontal unit (1 for a geographic CRS, whose units are degrees).
    z_unit_m : float
        Metres per height unit.
    """

    crs_wkt: str
    name: str
    xy_unit: str
    xy_unit_m: float
    z_unit_m: float


def cloud_crs(cloud: PointCloud, crs: Any = None, z_unit_m: float | None = None) -> CloudCrs:
    """The cloud's CRS (``crs`` overrides the file's) with its units checked.

    Raises
    ------
    CrsError
        If there is no CRS, it is not one a point can be placed by (projected or
        geographic), or its linear unit is unknown.
    """
    given = crs if crs is not None else cloud.crs_wkt
    if not given:
        raise CrsError(
            "the point cloud states no CRS (no WKT or GeoTIFF keys in the file); pass "
            "--crs EPSG:XXXX"
        )
    c = as_crs(given)
    h = horizontal_crs(c)
    if not (h.is_projected or h.is_geographic):
        raise CrsError(f"the points' CRS {h.name!r} is neither projected nor geographic")
    axis = h.axis_info[0] if h.axis_info else None
    factor = float(axis.unit_conversion_factor) if axis is not None else float("nan")
    unit = axis.unit_name if axis is not None else "unknown"
    if not (np.isfinite(factor) and factor > 0) or unit.lower() in ("unknown", ""):
        raise CrsError(f"the points' CRS {h.name!r} has an unknown unit ({unit!r})")
    k = z_unit_m_of(c) if z_unit_m is None else float(z_unit_m)
    if not (np.isfinite(k) and k > 0):
        raise CrsError(f"height unit must be a positive number of metres, got {z_unit_m}")
    return CloudCrs(c.to_wkt(), c.name, unit, 1.0 if h.is_geographic else factor, float(k))


def select_surface(
    cloud: PointCloud, surface: Literal["dtm", "dsm"], source: str = "the point cloud"
) -> PointCloud:
    """The points a terrain model (ground, class 2) or a surface model (first returns) uses.

    A cloud without return numbers (``.npy``/``.csv``) is used whole for a surface model.

    Raises
    ------
    InputFileError
        If a terrain model is asked of unclassified points or none is ground, or nothing
        is left.
    """
    if surface == "dtm":
        if cloud.classification is None:
            raise InputFileError(
                f"{source}: a terrain model (--surface dtm) needs classified points (LAS/LAZ "
                "class 2); use --surface dsm for unclassified points"
            )
        if not np.any(cloud.classification == GROUND_CLASS):
            raise InputFileError(
                f"{source}: no ground points (class {GROUND_CLASS}); classify the cloud "
                "first or use --surface dsm"
            )
        picked = cloud.select(ground_only=True)
    elif surface == "dsm":
        picked = cloud.select(first_returns=cloud.return_number is not None)
    else:
        raise InputFileError(f"surface must be 'dtm' or 'dsm', got {surface!r}")
    if len(picked) == 0:
        raise InputFileError(f"{source}: no points left for the {surface.upper()}")
    return picked


def anchor_for_cloud(
    xyz: np.ndarray, crs: CloudCrs, *, geoid_undulation_m: float | GeoidModel = 0.0
) -> LocalFrame:
    """A frame anchor at the centre of the cloud's footprint, on the ground.

    Parameters
    ----------
    xyz : ndarray, shape (n, 3)
        Points in ``crs`` (its units).
    crs : CloudCrs
    geoid_undulation_m : float or GeoidModel
        ``N`` (m), or the geoid evaluated at the anchor: the points' heights are
        orthometric and ``h = H * z_unit_m + N``; 0 when they are ellipsoidal.

    Returns
    -------
    LocalFrame
        Latitude and longitude of the centre of the points' bounding box (in their CRS),
        the height the median of the :data:`_ANCHOR_POINTS` points nearest to it, as WGS84
        ellipsoidal height. Rounded to 1e-7 deg and 1 mm.
    """
    from scipy.spatial import cKDTree

    pts = np.asarray(xyz, dtype=np.float64)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) == 0:
        raise InputFileError("no finite points to anchor the site on")
    lo, hi = pts[:, :2].min(axis=0), pts[:, :2].max(axis=0)
    centre = 0.5 * (lo + hi)
    k = min(_ANCHOR_POINTS, len(pts))
    _, idx = cKDTree(pts[:, :2]).query(centre, k=k)
    z0 = float(np.median(pts[np.atleast_1d(idx), 2]))
    h = horizontal_crs(crs.crs_wkt)
    lon, lat = cached_transformer(h.to_wkt(), "EPSG:4326").transform(centre[0], centre[1])
    if not (np.isfinite(lon) and np.isfinite(lat)):
        raise CrsError(f"the cloud's centre cannot be converted from {crs.name!r} to WGS84")
    n_m = float(as_geoid(geoid_undulation_m).undulation_m(lat, lon))
    h_m = z0 * crs.z_unit_m + n_m
    return LocalFrame(round(float(lat), 7), round(float(lon), 7), round(h_m, 3))
