"""Leave-one-out ground check of a GCP fit: the error that matters for geolocation.

Each GCP is left out, the camera refitted on the other GCPs the fit kept (same free
parameters, loss, bounds and priors), the GCP's pixel geolocated on the DEM (first
crossing of its ray) and compared with its surveyed position: a **horizontal** ground
error (m, in the site frame's east-north plane) and a **vertical** one (m, hit minus GCP
along the site frame's up axis), the two reported apart. Grazing rays, where the ray meets
the terrain at a shallow angle and a small angular error becomes a large ground error
(``m_per_px = range / f / sin(grazing)``), are reported with that amplification.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..raycast.cast import RayStatus, cast_rays
from ..terrain.dem import Dem
from .gcp_calibration import GcpFit, fit_camera_to_gcps
from .gcp_io import Gcp
from .pinhole import Camera

__all__ = ["LeaveOneOut", "leave_one_out"]


@dataclass(frozen=True, eq=False)
class LeaveOneOut:
    """Result of :func:`leave_one_out`; arrays of shape (k,), NaN where not available.

    Attributes
    ----------
    names : tuple of str
    reprojection_px : ndarray
        ``|residual|`` of the left-out GCP under the camera fitted without it.
    ground_error_m : ndarray
        **Horizontal** distance between the GCP and its pixel geolocated on the DEM by
        that camera (first crossing); also as ``horizontal_error_m``.
    vertical_error_m : ndarray
        Height of that hit minus the GCP's (m, site-frame up; signed).
    ground_error_3d_m : ndarray
        The 3-D distance.
    range_m : ndarray
        Camera-to-GCP distance.
    grazing_deg : ndarray
        Angle between the ray and the terrain surface at the GCP (90 = head-on).
    m_per_px : ndarray
        Ground displacement for a one-pixel error there, ``range / f / sin(grazing)``.
    grazing : ndarray of bool
        Rays below the grazing threshold.
    status : tuple of str
        ``"ok"``, ``"no hit"`` (ray misses the DEM), ``"off image"``, ``"too few"`` (not
        enough GCPs left to refit), ``"outlier"`` / ``"excluded"`` (a GCP the fit left
        out, as a reprojection outlier or on request: checked against the final fit,
        which did not use it).
    grazing_threshold_deg : float
    """

    names: tuple[str, ...]
    reprojection_px: np.ndarray
    ground_error_m: np.ndarray
    vertical_error_m: np.ndarray
    ground_error_3d_m: np.ndarray
    range_m: np.ndarray
    grazing_deg: np.ndarray
    m_per_px: np.ndarray
    grazing: np.ndarray
    status: tuple[str, ...]
    grazing_threshold_deg: float

    @property
    def horizontal_error_m(self) -> np.ndarray:
        """Horizontal ground error (m), the same array as ``ground_error_m``."""
        return self.ground_error_m


def _ground_check(
    camera: Camera, gcp: Gcp, dem: Dem, max_range_m: float
) -> tuple[float, float, float, float, float, float, str]:
    """(reproj px, horizontal m, vertical m, 3-D m, range m, grazing deg, status)."""
    u, v, _ = camera.project(gcp.p_enu)
    reproj = float(math.hypot(u[0] - gcp.u, v[0] - gcp.v))
    d = gcp.p_enu - camera.position_enu
    rng = float(np.linalg.norm(d))
    gx, gy = dem.gradient(np.array([gcp.p_enu[0]]), np.array([gcp.p_enu[1]]))
    normal = np.array([-float(np.nan_to_num(gx[0])), -float(np.nan_to_num(gy[0])), 1.0])
    normal /= np.linalg.norm(normal)
    graze = math.degrees(math.asin(min(1.0, abs(float(d @ normal)) / max(rng, 1e-300))))
    nan = math.nan
    if not camera.in_image(gcp.u, gcp.v):
        return reproj, nan, nan, nan, rng, graze, "off image"
    origin, direction = camera.pixel_to_ray(gcp.u, gcp.v)
    hits = cast_rays(dem, origin, direction, max_range_m, mode="first")
    if int(hits.status[0]) != RayStatus.HIT or hits.counts[0] == 0:
        return reproj, nan, nan, nan, rng, graze, "no hit"
    p = hits.points[0]
    err_h = float(math.hypot(p[0] - gcp.p_enu[0], p[1] - gcp.p_enu[1]))
    err_v = float(p[2] - gcp.p_enu[2])
    err_3d = float(np.linalg.norm(p - gcp.p_enu))
    return reproj, err_h, err_v, err_3d, rng, graze, "ok"


def leave_one_out(
    gcps: Sequence[Gcp],
    fit: GcpFit,
    dem: Dem,
    *,
    grazing_threshold_deg: float = 5.0,
    max_range_m: float = 20_000.0,
    pixel_sigma_px: float = 1.0,
) -> LeaveOneOut:
    """Leave-one-out ground check of a fit (see the module notes).

    Parameters
    ----------
    gcps : sequence of Gcp
        The GCPs given to :func:`fit_camera_to_gcps`.
    fit : GcpFit
        The full fit: its free parameters, loss, bounds and priors are reused and each
        refit starts from its camera. GCPs it excluded are left out of every refit and
        checked against the final camera, which did not use them.
    dem : Dem
    grazing_threshold_deg : float
        Rays meeting the terrain at less than this are flagged as grazing.
    max_range_m : float
        How far rays are followed.
    pixel_sigma_px : float
        As given to the fit (weighs its priors).
    """
    k, p = len(gcps), len(fit.free)
    out = np.full((8, k), np.nan)
    status: list[str] = []
    n_priors = len(fit.priors)
    for i in range(k):
        if fit.excluded[i]:
            cam, st = fit.camera, ("outlier" if fit.outliers[i] else "excluded")
        else:
            rest = [g for j, g in enumerate(gcps) if j != i and not fit.excluded[j]]
            if 2 * len(rest) + n_priors <= p:
                status.append("too few")
                continue
            sub = fit_camera_to_gcps(
                fit.camera,
                rest,
                fit.free,
                loss=fit.loss,
                f_scale_px=fit.f_scale_px,
                outlier_px=math.inf,
                bounds=_widened(fit),
                priors=fit.priors,
                pixel_sigma_px=pixel_sigma_px,
                kabsch=False,
            )
            cam, st = sub.camera, "ok"
        reproj, eh, ev, e3, rng, graze, gst = _ground_check(cam, gcps[i], dem, max_range_m)
        f = cam.intrinsics.fx
        m_px = rng / f / max(math.sin(math.radians(graze)), 1e-9)
        out[:, i] = [reproj, eh, ev, e3, rng, graze, m_px, 0.0]
        status.append(st if gst == "ok" else gst)
    grazing = np.where(np.isfinite(out[5]), out[5] < grazing_threshold_deg, False)
    return LeaveOneOut(
        names=tuple(g.name for g in gcps),
        reprojection_px=out[0],
        ground_error_m=out[1],
        vertical_error_m=out[2],
        ground_error_3d_m=out[3],
        range_m=out[4],
        grazing_deg=out[5],
        m_per_px=out[6],
        grazing=grazing,
        status=tuple(status),
        grazing_threshold_deg=float(grazing_threshold_deg),
    )


def _widened(fit: GcpFit) -> dict[str, tuple[float, float]]:
    """The fit's bounds, widened to hold its solution (a refit starts there)."""
    out = {}
    for name, (lo, hi) in fit.bounds.items():
        value = fit.values[name]
        if name == "yaw":
            out[name] = (lo, hi)
            continue
        out[name] = (min(lo, value), max(hi, value))
    return out
