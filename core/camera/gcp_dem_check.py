"""Every GCP checked against the DEM: its height, and whether the camera's ray reaches it.

Two tests per GCP, both in the site frame:

* **height**: ``dh = z_gcp - z_dem(e, n)``, the surveyed height minus the DEM's bilinear
  height at the GCP's east/north. ``|dh|`` above the tolerance
  ``tol = max(height_tol_m, 3 * sigma_dem)`` (``sigma_dem`` from the DEM's variance band
  there) flags the GCP: it is not on the terrain the geolocation will intersect (a
  rooftop, a mast, a survey in another vertical datum, or a DEM that smooths it away).
* **ray**: the ray from the fitted camera's centre *towards the surveyed point* is cast
  on the DEM (first crossing). It *reaches* the GCP when that crossing is within
  ``tol / sin(grazing)`` of the point along the ray (the along-ray length that a height
  error ``tol`` makes at that grazing angle). Otherwise the ray *passes over* (the first
  crossing lies beyond the GCP, or there is none: the point floats above the terrain as
  seen) or is *blocked* (the terrain is crossed before the GCP: it is hidden or below the
  surface).

A GCP outside the DEM's hull of cell centres is an input error; one over a DEM hole is
flagged ``"over a DEM hole"``.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import CalibrationError
from ..raycast.cast import RayStatus, cast_rays
from ..terrain.dem import Dem
from .gcp_io import Gcp
from .pinhole import Camera

__all__ = ["RAY_STATUSES", "DemCheck", "check_gcps_on_dem", "check_gcps_inside_dem"]

#: Values of :attr:`DemCheck.ray`.
RAY_STATUSES = ("reaches", "passes over", "blocked", "over a DEM hole")


@dataclass(frozen=True, eq=False)
class DemCheck:
    """Result of :func:`check_gcps_on_dem`; arrays of shape (k,).

    Attributes
    ----------
    names : tuple of str
    dem_z_m : ndarray
        DEM height at each GCP's east/north (m, site-frame up; NaN over a hole).
    dh_m : ndarray
        Surveyed height minus DEM height (m; positive = above the terrain).
    tolerance_m : ndarray
        The height tolerance used at each GCP (m).
    ray : tuple of str
        One of :data:`RAY_STATUSES`.
    ray_miss_m : ndarray
        Range of the first crossing minus range of the GCP along its ray (m; positive =
        the ray passes beyond the GCP, negative = blocked before it; NaN with no crossing).
    grazing_deg : ndarray
        Angle between that ray and the terrain at the GCP (deg, 90 = head-on).
    flagged : ndarray of bool
        Inconsistent with the DEM (height or ray).
    reasons : tuple of str
        Why, per GCP (empty string when consistent).
    """

    names: tuple[str, ...]
    dem_z_m: np.ndarray
    dh_m: np.ndarray
    tolerance_m: np.ndarray
    ray: tuple[str, ...]
    ray_miss_m: np.ndarray
    grazing_deg: np.ndarray
    flagged: np.ndarray
    reasons: tuple[str, ...]


def check_gcps_inside_dem(gcps: Sequence[Gcp], dem: Dem) -> None:
    """Refuse GCPs outside the DEM's hull of cell centres.

    Raises
    ------
    CalibrationError
        Naming the first such GCP and the DEM's extent.
    """
    x0, y0, x1, y1 = dem.grid.centre_bounds
    for g in gcps:
        e, n = float(g.p_enu[0]), float(g.p_enu[1])
        if not (x0 <= e <= x1 and y0 <= n <= y1):
            raise CalibrationError(
                f"GCP {g.name!r} at E {e:.1f} N {n:.1f} m is outside the DEM (E {x0:.1f} .. "
                f"{x1:.1f}, N {y0:.1f} .. {y1:.1f}); check its coordinates and CRS"
            )


def check_gcps_on_dem(
    camera: Camera,
    gcps: Sequence[Gcp],
    dem: Dem,
    *,
    height_tol_m: float = 0.5,
    max_range_m: float = 20_000.0,
) -> DemCheck:
    """Check each GCP's height and ray against the DEM (see the module notes).

    Parameters
    ----------
    camera : Camera
        The fitted camera (its centre casts the rays).
    gcps : sequence of Gcp
        Site-frame control points.
    dem : Dem
    height_tol_m : float
        Smallest height tolerance (m).
    max_range_m : float
        How far rays are followed (beyond the farthest GCP).

    Raises
    ------
    CalibrationError
        When a GCP lies outside the DEM.
    """
    check_gcps_inside_dem(gcps, dem)
    p = np.array([g.p_enu for g in gcps], dtype=np.float64).reshape(-1, 3)
    z = dem.sample(p[:, 0], p[:, 1]).astype(np.float64)
    var = dem.sample_variance(p[:, 0], p[:, 1]).astype(np.float64)
    tol = np.maximum(height_tol_m, 3.0 * np.sqrt(np.nan_to_num(np.maximum(var, 0.0))))
    dh = p[:, 2] - z
    d = p - camera.position_enu
    rng = np.linalg.norm(d, axis=1)
    direction = d / np.maximum(rng, 1e-300)[:, None]
    origins = np.broadcast_to(camera.position_enu, p.shape).copy()
    far = max(float(max_range_m), float(rng.max()) * 1.5 + 100.0)
    hits = cast_rays(dem, origins, direction, far, mode="first")
    gx, gy = dem.gradient(p[:, 0], p[:, 1])
    normal = np.column_stack([-np.nan_to_num(gx), -np.nan_to_num(gy), np.ones(len(p))])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    sin_g = np.clip(np.abs(np.sum(direction * normal, axis=1)), 1e-6, 1.0)
    graze = np.degrees(np.arcsin(sin_g))
    miss = np.full(len(p), np.nan)
    ray: list[str] = []
    flagged = np.zeros(len(p), bool)
    reasons: list[str] = []
    for i in range(len(p)):
        why: list[str] = []
        if not math.isfinite(z[i]):
            ray.append("over a DEM hole")
            reasons.append("over a DEM hole")
            flagged[i] = True
            continue
        if abs(dh[i]) > tol[i]:
            where = "above" if dh[i] > 0 else "below"
            why.append(f"height {abs(dh[i]):.2f} m {where} the DEM (tolerance {tol[i]:.2f} m)")
        hit = int(hits.status[i]) == RayStatus.HIT and hits.counts[i] > 0
        if hit:
            q = hits.points[hits.offsets[i]]
            miss[i] = float(np.linalg.norm(q - camera.position_enu)) - rng[i]
        allowed = tol[i] / sin_g[i]
        if hit and abs(miss[i]) <= allowed:
            ray.append("reaches")
        elif not hit or miss[i] > allowed:
            ray.append("passes over")
            why.append(
                "ray passes over it"
                + (f" (meets the terrain {miss[i]:.1f} m beyond)" if hit else " (no crossing)")
            )
        else:
            ray.append("blocked")
            why.append(f"ray blocked {-miss[i]:.1f} m before it")
        flagged[i] = bool(why)
        reasons.append("; ".join(why))
    for arr in (z, dh, tol, miss, graze, flagged):
        arr.setflags(write=False)
    return DemCheck(
        names=tuple(g.name for g in gcps),
        dem_z_m=z,
        dh_m=dh,
        tolerance_m=tol,
        ray=tuple(ray),
        ray_miss_m=miss,
        grazing_deg=graze,
        flagged=flagged,
        reasons=tuple(reasons),
    )
