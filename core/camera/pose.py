"""Camera poses surveyed in WGS84 or a projected CRS, brought into the site frame.

A surveyed pose is a position (in any CRS, with a stated vertical datum) and an
orientation measured *at the camera*:

* azimuth of the optical axis, clockwise from north. Either **true** north (the
  geodetic meridian through the camera; what a compass corrected for declination, a
  sun shot or a GNSS heading gives), or **grid** north of a projected CRS (what a bearing
  taken off a UTM or state-plane map or computed from two grid coordinates gives). A grid
  azimuth becomes a true one by adding the meridian convergence ``gamma`` at the camera
  (``true = grid + gamma``; +0.89 deg at Bushy Run in UTM 17N), measured through the
  same pyproj conversion as the position (:func:`grid_convergence_deg`: PROJ's
  ``Proj.get_factors`` value on WGS84-based grids, plus the datum shift's turn on older
  ones). Ignoring it turns the view by ``gamma``: 16 m of ground error at 1 km for
  0.9 deg.
* tilt (elevation of the axis, negative looks down) against the horizontal at the
  camera, i.e. the plane normal to the WGS84 ellipsoid normal there. A levelled
  instrument's plumb line differs from that normal by the deflection of the vertical
  (a few arc seconds; not modelled).
* roll about the optical axis (positive lowers the image's right side).

A photogrammetric pose (bundle adjustment, aerial triangulation, drone metadata) is a
rotation matrix instead, or its omega-phi-kappa angles, whose world axes are the grid axes
of the pose's CRS (easting, northing, height) at the camera: :func:`pose_from_rotation`.
Grid north differs from true north by ``gamma`` there, so the matrix is turned about the
vertical by ``gamma`` into the camera's own east-north-up frame, then into the site frame
as above. The projection's scale factor (UTM's 0.9996 to 1.0004) is not a rotation and
does not enter: a camera's angles are the same in any conformal grid.

The site frame's axes are those of the tangent plane at the site anchor, not at the
camera: at 1 km from the anchor its north differs from the camera's true north by
``dlon * sin(lat)`` (0.004 deg at 40 deg N) and its up from the camera's vertical by
``d / R`` (0.009 deg). The conversion rotates the camera's own east-north-up frame into
the site frame exactly (through ECEF), so both are accounted for; the returned site-frame
angles therefore differ slightly from the surveyed ones.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from ..errors import CameraError, SiteError
from ..geo.geodesy import (
    LocalFrame,
    cached_transformer,
    horizontal_crs,
    meridian_convergence_deg,
)
from ..terrain.dem import Dem
from .pinhole import Camera, Intrinsics, rotation_from_azimuth_tilt_roll

__all__ = [
    "SurveyedPose",
    "check_camera_on_dem",
    "grid_convergence_deg",
    "pose_from_rotation",
    "pose_from_survey",
    "rotation_from_opk_deg",
    "true_azimuth_deg",
]

#: Photogrammetric camera axes (x right, y up, z backwards) to OpenCV's (y down, z forward).
_FLIP_YZ = np.diag([1.0, -1.0, -1.0])

North = Literal["true", "grid"]


def true_azimuth_deg(
    az_deg: float, north: North, crs: Any, lat_deg: float, lon_deg: float
) -> tuple[float, float]:
    """Azimuth clockwise from true north, and the convergence used.

    Parameters
    ----------
    az_deg : float
        Measured azimuth (degrees clockwise).
    north : {"true", "grid"}
        What ``az_deg`` is measured from.
    crs : CRS-like
        The projected CRS whose grid north is meant (ignored for ``"true"``).
    lat_deg, lon_deg : float
        WGS84 position of the camera.

    Returns
    -------
    (az_true_deg, gamma_deg) : float
        ``az_true = az + gamma`` for grid azimuths (``gamma`` = angle from true to grid
        north, clockwise), ``gamma = 0`` for true ones.

    Raises
    ------
    CameraError
        For a grid azimuth in a geographic CRS (it has no grid north).
    """
    if north == "true":
        return float(az_deg), 0.0
    if north != "grid":
        raise CameraError(f"north must be 'true' or 'grid', got {north!r}")
    if not horizontal_crs(crs).is_projected:
        raise CameraError(
            "a grid azimuth needs a projected CRS; this one is geographic (use --north true)"
        )
    gamma = float(meridian_convergence_deg(crs, lat_deg, lon_deg))
    return float(az_deg) + gamma, gamma


@dataclass(frozen=True, eq=False)
class SurveyedPose:
    """A surveyed camera pose expressed in the site frame.

    Attributes
    ----------
    camera : Camera
        The camera in the site frame.
    lat_deg, lon_deg, h_m : float
        WGS84 position of the optical centre (``h_m`` ellipsoidal).
    az_true_deg : float
        The azimuth from true north at the camera (after grid-north correction).
    convergence_deg : float
        Meridian convergence applied (0 for a true azimuth).
    site_az_deg, site_tilt_deg, site_roll_deg : float
        The same orientation as angles of the site frame (see the module notes).
    """

    camera: Camera
    lat_deg: float
    lon_deg: float
    h_m: float
    az_true_deg: float
    convergence_deg: float
    site_az_deg: float
    site_tilt_deg: float
    site_roll_deg: float


def pose_from_survey(
    frame: LocalFrame,
    intrinsics: Intrinsics,
    x: float,
    y: float,
    z: float,
    crs: Any,
    az_deg: float,
    tilt_deg: float,
    roll_deg: float = 0.0,
    *,
    north: North = "true",
    geoid_undulation_m: float = 0.0,
    z_unit_m: float | None = None,
) -> SurveyedPose:
    """Bring a surveyed camera pose into the site frame.

    Parameters
    ----------
    frame : LocalFrame
    intrinsics : Intrinsics
    x, y, z : float
        Optical centre in ``crs``: easting/northing (projected, the CRS's unit) or
        longitude/latitude (geographic, degrees), and height in ``z_unit_m``.
    crs : CRS-like
    az_deg, tilt_deg, roll_deg : float
        Orientation measured at the camera (see the module notes).
    north : {"true", "grid"}
        Reference of ``az_deg``.
    geoid_undulation_m : float
        ``N`` for an orthometric ``z`` (``h = z * z_unit_m + N``); 0 for ellipsoidal.
    z_unit_m : float, optional
        Metres per height unit; default from the CRS.
    """
    if not -90.0 <= float(tilt_deg) <= 90.0:
        raise CameraError(f"tilt_deg must be within [-90, 90], got {tilt_deg}")
    p_enu, (lat, lon, h) = _position(frame, x, y, z, crs, geoid_undulation_m, z_unit_m)
    az_true, gamma = true_azimuth_deg(az_deg, north, crs, lat, lon)
    if north == "grid":
        # Measured through the position's own conversion (datum shift included), as for
        # rotation matrices: the formula at the WGS84 position is off on older datums.
        gamma = grid_convergence_deg(crs, x, y)
        az_true = float(az_deg) + gamma
    r_local_cam = rotation_from_azimuth_tilt_roll(az_true, float(tilt_deg), float(roll_deg))
    return _in_site(frame, intrinsics, p_enu, (lat, lon, h), r_local_cam, az_true, gamma)


def _position(
    frame: LocalFrame,
    x: float,
    y: float,
    z: float,
    crs: Any,
    geoid_undulation_m: float,
    z_unit_m: float | None,
) -> tuple[np.ndarray, tuple[float, float, float]]:
    """The optical centre in the site frame, shape (3,), and its WGS84 lat, lon, h."""
    e, n, u = frame.to_enu_from_crs(
        x, y, z, crs, geoid_undulation_m=geoid_undulation_m, z_unit_m=z_unit_m
    )
    p_enu = np.array([float(e), float(n), float(u)])
    lat, lon, h = (float(v) for v in frame.to_geodetic(*p_enu))
    return p_enu, (lat, lon, h)


def _in_site(
    frame: LocalFrame,
    intrinsics: Intrinsics,
    p_enu: np.ndarray,
    llh: tuple[float, float, float],
    r_local_cam: np.ndarray,
    az_true_deg: float,
    gamma_deg: float,
) -> SurveyedPose:
    """Turn ``R_local_cam`` (camera's own true ENU) into the site frame and build the pose."""
    lat, lon, h = llh
    at_camera = LocalFrame(lat, lon, h)
    # camera -> camera's own ENU -> ECEF -> site ENU
    r_site_cam = frame.R_enu_ecef @ at_camera.R_enu_ecef.T @ r_local_cam
    # Re-orthonormalise the product (round-off only) so Camera accepts it.
    uu, _, vt = np.linalg.svd(r_site_cam)
    r_site_cam = uu @ vt
    camera = Camera(intrinsics, p_enu, r_site_cam)
    az_s, tilt_s, roll_s = camera.azimuth_tilt_roll_deg()
    return SurveyedPose(camera, lat, lon, h, az_true_deg % 360.0, gamma_deg, az_s, tilt_s, roll_s)


def rotation_from_opk_deg(omega_deg: float, phi_deg: float, kappa_deg: float) -> np.ndarray:
    """``R_world_cam`` (OpenCV camera axes) from photogrammetric omega, phi, kappa.

    The convention of Pix4D, Agisoft Metashape's OPK export and weitsicht: the
    camera-to-world rotation of a camera whose axes are x right, y up, z backwards (it
    looks along -z) is ``R = Rx(omega) Ry(phi) Rz(kappa)``, each a right-handed rotation
    about a world axis (``Rx(a) = [[1, 0, 0], [0, cos a, -sin a], [0, sin a, cos a]]``).
    The OpenCV-axes matrix is ``R @ diag(1, -1, -1)``. A nadir camera with the image top
    to the north has ``omega = phi = kappa = 0``.

    Parameters
    ----------
    omega_deg, phi_deg, kappa_deg : float
        Angles (degrees) about the world's first (east), second (north) and third (up)
        axis.

    Returns
    -------
    ndarray, shape (3, 3)
        Columns are the OpenCV camera x (right), y (down), z (forward) axes in world axes.
    """
    o, p, k = (math.radians(float(a)) for a in (omega_deg, phi_deg, kappa_deg))
    rx = np.array(
        [[1.0, 0.0, 0.0], [0.0, math.cos(o), -math.sin(o)], [0.0, math.sin(o), math.cos(o)]]
    )
    ry = np.array(
        [[math.cos(p), 0.0, math.sin(p)], [0.0, 1.0, 0.0], [-math.sin(p), 0.0, math.cos(p)]]
    )
    rz = np.array(
        [[math.cos(k), -math.sin(k), 0.0], [math.sin(k), math.cos(k), 0.0], [0.0, 0.0, 1.0]]
    )
    return rx @ ry @ rz @ _FLIP_YZ


def grid_convergence_deg(crs: Any, x: float, y: float) -> float:
    """True azimuth of the grid-north direction at ``(x, y)`` of a projected CRS (degrees).

    Measured, not taken from the projection's formula: the points 10 units south and
    north of ``(x, y)`` are converted to WGS84 as demtrack converts positions (pyproj,
    datum shift included), and the WGS84 ellipsoid's azimuth between them at their
    midpoint is returned.
    For a CRS on WGS84 (UTM) this is the meridian convergence ``gamma`` to 1e-9 deg. On
    an older datum it also holds the datum shift's turn: for MGI / Austria Lambert the
    formula at the WGS84 position is 0.002 deg off (a 250 m datum shift moves the point
    along the projection), and the grid rotation weitsicht computes between UTM 33N and
    Lambert is matched to 5e-5 deg. Geographic CRSs give 0.
    """
    hcrs = horizontal_crs(crs)
    if not hcrs.is_projected:
        return 0.0
    from pyproj import Geod

    tr = cached_transformer(hcrs.to_wkt(), "EPSG:4326")
    lon, lat = tr.transform([float(x), float(x)], [float(y) - 10.0, float(y) + 10.0])
    az12, az21, _ = Geod(ellps="WGS84").inv(lon[0], lat[0], lon[1], lat[1])
    # The chord's azimuths at its two ends differ from the grid line's by the arc-to-chord
    # correction, in opposite senses (1.3e-6 deg for 20 m at 120 km from the UTM central
    # meridian): their mean is the azimuth at the midpoint, (x, y).
    fwd2 = az21 + 180.0
    return float(az12 + 0.5 * ((fwd2 - az12 + 180.0) % 360.0 - 180.0))


def pose_from_rotation(
    frame: LocalFrame,
    intrinsics: Intrinsics,
    x: float,
    y: float,
    z: float,
    crs: Any,
    R_world_cam: Any,  # noqa: N803 - frame names follow the project's convention
    *,
    north: North | None = None,
    geoid_undulation_m: float = 0.0,
    z_unit_m: float | None = None,
) -> SurveyedPose:
    """Bring a photogrammetric pose (position and rotation matrix) into the site frame.

    Parameters
    ----------
    frame : LocalFrame
    intrinsics : Intrinsics
    x, y, z : float
        Optical centre in ``crs`` (as :func:`pose_from_survey`).
    crs : CRS-like
    R_world_cam : array_like, shape (3, 3)
        Rotation of OpenCV camera vectors (x right, y down, z forward) into the world
        axes: the grid axes (easting, northing, up) of a projected ``crs`` when ``north``
        is ``"grid"``, or east, true north, up at the camera when ``"true"``. Must be a
        proper rotation to 1e-6 (exports round to about 1e-10); it is re-orthonormalised.
        Use :func:`rotation_from_opk_deg` for omega-phi-kappa angles.
    north : {"grid", "true"}, optional
        Default ``"grid"`` for a projected CRS (what photogrammetric software exports),
        ``"true"`` for a geographic one (it has no grid).
    geoid_undulation_m, z_unit_m : float
        As :func:`pose_from_survey`.

    Raises
    ------
    CameraError
        On a matrix that is not a finite proper rotation, or a grid north asked of a
        geographic CRS.
    """
    rot = np.asarray(R_world_cam, dtype=np.float64)
    if rot.shape != (3, 3) or not np.isfinite(rot).all():
        raise CameraError(f"R_world_cam must be a finite 3x3 matrix, got shape {rot.shape}")
    err = float(np.abs(rot.T @ rot - np.eye(3)).max())
    if err > 1e-6 or np.linalg.det(rot) <= 0.0:
        raise CameraError(
            "R_world_cam must be a proper rotation (orthonormal to 1e-6, determinant +1); "
            f"this one is off by {err:.2g} with determinant {np.linalg.det(rot):.6g}"
        )
    uu, _, vt = np.linalg.svd(rot)
    rot = uu @ vt
    if north is None:
        north = "grid" if horizontal_crs(crs).is_projected else "true"
    p_enu, (lat, lon, h) = _position(frame, x, y, z, crs, geoid_undulation_m, z_unit_m)
    # A grid direction at grid azimuth a has true azimuth a + gamma: turn it clockwise
    # by gamma about the vertical.
    true_azimuth_deg(0.0, north, crs, lat, lon)  # refuses a grid north of degrees
    gamma = grid_convergence_deg(crs, x, y) if north == "grid" else 0.0
    g = math.radians(gamma)
    r_true_grid = np.array(
        [[math.cos(g), math.sin(g), 0.0], [-math.sin(g), math.cos(g), 0.0], [0.0, 0.0, 1.0]]
    )
    r_local_cam = r_true_grid @ rot
    # The optical axis's true azimuth; looking straight down, the image top's instead.
    axis = r_local_cam[:, 2] if math.hypot(*r_local_cam[:2, 2]) > 1e-9 else -r_local_cam[:, 1]
    az_true = math.degrees(math.atan2(axis[0], axis[1]))
    return _in_site(frame, intrinsics, p_enu, (lat, lon, h), r_local_cam, az_true, gamma)


def check_camera_on_dem(sensor_id: str, position_enu: np.ndarray, dem: Dem) -> None:
    """Refuse a camera that is not above the DEM.

    Raises
    ------
    SiteError
        When the optical centre is outside the DEM's hull of cell centres, over a hole,
        or below the terrain surface.
    """
    e, n, u = (float(v) for v in position_enu)
    z = float(dem.sample(np.array([e]), np.array([n]))[0])
    x0, y0, x1, y1 = dem.grid.centre_bounds
    if not (x0 <= e <= x1 and y0 <= n <= y1):
        raise SiteError(
            f"camera {sensor_id!r} at E {e:.1f} N {n:.1f} m is outside the DEM "
            f"(E {x0:.1f} .. {x1:.1f}, N {y0:.1f} .. {y1:.1f}); check its position and CRS"
        )
    if not math.isfinite(z):
        raise SiteError(f"camera {sensor_id!r} at E {e:.1f} N {n:.1f} m is over a hole in the DEM")
    if u < z:
        raise SiteError(
            f"camera {sensor_id!r} is {z - u:.2f} m below the terrain (U {u:.2f} m, DEM "
            f"{z:.2f} m); check its height and vertical datum"
        )
