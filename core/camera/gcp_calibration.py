"""Camera calibration from ground control points (GCPs) by robust least squares.

A GCP is a pixel ``(u, v)`` whose world position is known (surveyed, or read off an
orthophoto and the DEM). The fit adjusts the chosen camera parameters so that the GCPs
project onto their pixels:

``yaw, tilt, roll``
    orientation (degrees; azimuth clockwise from the site frame's north, elevation,
    bank about the optical axis; see
    :func:`~demtrack.core.camera.pinhole.rotation_from_azimuth_tilt_roll`),
``f``
    focal length in pixels (``fx``; ``fy`` keeps its ratio to ``fx``),
``cx, cy``
    principal point (pixels),
``k1, k2``
    radial distortion (OpenCV),
``x, y, z``
    optical centre (m, site frame; free it only with many well spread GCPs).

Cost: the reprojection residuals in pixels under a robust loss (``scipy.optimize.
least_squares``, trust-region reflective, ``soft_l1`` by default with a scale of 1 px),
which bounds a blunder's pull. Outliers are then *flagged*, not silently down-weighted:
a GCP whose residual exceeds the threshold (``outlier_px``, default ``max(3 px, 4
sigma)`` with ``sigma`` the per-axis noise estimated robustly from the median residual,
``median |r| / 1.1774`` for a 2-D Gaussian) is excluded and the fit repeated until the
flagged set is stable. Flagged GCPs are reported with their residual from the final fit.

Orientation start: the Kabsch/Wahba rotation that best aligns the GCPs' pixel rays with
their directions from the camera, taken when it fits better than the site's pose, so a
start several tens of degrees off still converges.

Leave-one-out check (:func:`leave_one_out`): each GCP is left out, the camera refitted on
the other inliers, the GCP's pixel geolocated on the DEM (first crossing of its ray) and
compared with its surveyed position: a ground error in metres, the figure that matters
for geolocation. Grazing rays, where the ray meets the terrain at a shallow angle and a
small angular error becomes a large ground error (``m_per_px = range / f / sin(grazing)``),
are reported with that amplification.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from ..errors import CalibrationError, CameraError
from ..raycast.cast import RayStatus, cast_rays
from ..terrain.dem import Dem
from .gcp_io import Gcp
from .pinhole import (
    Camera,
    Intrinsics,
    distort_normalized,
    rotation_from_azimuth_tilt_roll,
)

__all__ = [
    "DEFAULT_FREE",
    "FREE_PARAMETERS",
    "GcpFit",
    "LeaveOneOut",
    "check_gcps_in_front",
    "fit_camera_to_gcps",
    "leave_one_out",
    "parse_free",
]

#: Parameters that can be freed, in the order of the parameter vector.
FREE_PARAMETERS = ("yaw", "tilt", "roll", "f", "cx", "cy", "k1", "k2", "x", "y", "z")
#: Parameters freed by default: the orientation.
DEFAULT_FREE = ("yaw", "tilt", "roll")
_BEHIND_PX = 1e4  # residual given to a GCP behind the camera during the search
_RAYLEIGH_MEDIAN = math.sqrt(2.0 * math.log(2.0))  # median of |r| / sigma for 2-D noise


def parse_free(text: str) -> tuple[str, ...]:
    """``"yaw,tilt,f"`` -> ``("yaw", "tilt", "f")`` in canonical order.

    Raises
    ------
    CalibrationError
        On an unknown or repeated name, or an empty list.
    """
    names = [t.strip().lower() for t in text.split(",") if t.strip()]
    unknown = [n for n in names if n not in FREE_PARAMETERS]
    if unknown:
        raise CalibrationError(
            f"unknown parameter(s) {', '.join(unknown)}; choose from {','.join(FREE_PARAMETERS)}"
        )
    if not names:
        raise CalibrationError("no parameter to fit: --free must name at least one")
    if len(set(names)) != len(names):
        raise CalibrationError(f"--free names a parameter twice: {text}")
    return tuple(n for n in FREE_PARAMETERS if n in names)


# --------------------------------------------------------------------------- model


def _params_of(camera: Camera) -> np.ndarray:
    az, tilt, roll = camera.azimuth_tilt_roll_deg()
    i = camera.intrinsics
    return np.array([az, tilt, roll, i.fx, i.cx, i.cy, i.k1, i.k2, *camera.position_enu])


def _project(theta: np.ndarray, base: Intrinsics, p_enu: np.ndarray) -> np.ndarray:
    """Pixels ``(n, 2)`` of points for a full parameter vector; NaN behind the camera."""
    az, tilt, roll, fx, cx, cy, k1, k2 = theta[:8]
    r = rotation_from_azimuth_tilt_roll(az, tilt, roll)
    p_cam = (p_enu - theta[8:11]) @ r
    z = p_cam[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        xn = np.where(z > 0, p_cam[:, 0] / z, np.nan)
        yn = np.where(z > 0, p_cam[:, 1] / z, np.nan)
    xd, yd = distort_normalized(xn, yn, k1, k2, base.p1, base.p2, base.k3)
    fy = fx * base.fy / base.fx
    return np.column_stack([fx * xd + cx, fy * yd + cy])


def _camera_of(theta: np.ndarray, base: Intrinsics) -> Camera:
    az, tilt, roll, fx, cx, cy, k1, k2 = (float(t) for t in theta[:8])
    try:
        intr = Intrinsics(
            fx, fx * base.fy / base.fx, cx, cy, base.width, base.height,
            k1, k2, base.p1, base.p2, base.k3,
        )  # fmt: skip
    except CameraError as exc:
        raise CalibrationError(
            f"the fitted lens model is unusable ({exc}); free fewer distortion terms"
        ) from None
    tilt = min(90.0, max(-90.0, tilt))
    return Camera.from_azimuth_tilt_roll(intr, theta[8:11], az % 360.0, tilt, roll)


def _kabsch_start(camera: Camera, gcps: Sequence[Gcp]) -> tuple[float, float, float] | None:
    """Angles of the rotation best aligning the pixel rays with the GCP directions."""
    if len(gcps) < 3:
        return None
    u = np.array([g.u for g in gcps])
    v = np.array([g.v for g in gcps])
    xn, yn = camera.intrinsics.undistort(u, v)
    c = np.column_stack([xn, yn, np.ones_like(xn)])
    w = np.array([g.p_enu for g in gcps]) - camera.position_enu
    if not (np.isfinite(c).all() and np.isfinite(w).all()):
        return None
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    norms = np.linalg.norm(w, axis=1, keepdims=True)
    if (norms == 0).any():
        return None
    w /= norms
    h = c.T @ w  # sum of c_i w_i^T
    uu, s, vt = np.linalg.svd(h)
    if s[1] < 1e-9 * max(s[0], 1e-300):  # collinear rays: rotation about them undefined
        return None
    d = np.sign(np.linalg.det(vt.T @ uu.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ uu.T  # R c_i ~ w_i: camera -> world
    try:
        return Camera(camera.intrinsics, camera.position_enu, r).azimuth_tilt_roll_deg()
    except CameraError:
        return None


# --------------------------------------------------------------------------- results


@dataclass(frozen=True, eq=False)
class GcpFit:
    """Result of :func:`fit_camera_to_gcps`.

    Attributes
    ----------
    camera : Camera
        The fitted camera.
    free : tuple of str
        Parameters fitted.
    values : dict of str to float
        Fitted value of each free parameter.
    sigmas : dict of str to float
        1-sigma of each free parameter from the inliers' residual scatter (NaN with no
        redundancy).
    names : tuple of str
        GCP names, in input order.
    residuals_px : ndarray, shape (k, 2)
        Projected minus observed pixel for every GCP (outliers included).
    outliers : ndarray of bool, shape (k,)
        GCPs whose residual exceeds the threshold.
    excluded : ndarray of bool, shape (k,)
        Flagged GCPs left out of the final fit (all of them, unless too few GCPs would
        remain or outlier rejection was turned off).
    threshold_px : float
        The residual magnitude above which a GCP is flagged.
    rmse_px : float
        Root mean square of ``|residual|`` over the inliers.
    loss : str
        The robust loss used.
    converged : bool
        Whether the optimiser reported convergence.
    warnings : tuple of str
    """

    camera: Camera
    free: tuple[str, ...]
    values: dict[str, float]
    sigmas: dict[str, float]
    names: tuple[str, ...]
    residuals_px: np.ndarray
    outliers: np.ndarray
    excluded: np.ndarray
    threshold_px: float
    rmse_px: float
    loss: str
    converged: bool
    warnings: tuple[str, ...] = field(default=())

    @property
    def residual_norms_px(self) -> np.ndarray:
        """``|residual|`` per GCP (px), shape (k,)."""
        return np.hypot(self.residuals_px[:, 0], self.residuals_px[:, 1])


@dataclass(frozen=True, eq=False)
class LeaveOneOut:
    """Result of :func:`leave_one_out`; arrays of shape (k,), NaN where not available.

    Attributes
    ----------
    names : tuple of str
    reprojection_px : ndarray
        ``|residual|`` of the left-out GCP under the camera fitted without it.
    ground_error_m : ndarray
        Horizontal distance between the GCP and its pixel geolocated on the DEM by that
        camera (first crossing).
    ground_error_3d_m : ndarray
        The same, in 3-D.
    range_m : ndarray
        Camera-to-GCP distance.
    grazing_deg : ndarray
        Angle between the ray and the terrain surface at the GCP (90 = head-on).
    m_per_px : ndarray
        Ground displacement for a one-pixel error there, ``range / f / sin(grazing)``.
    grazing : ndarray of bool
        Rays below the grazing threshold.
    status : tuple of str
        ``"ok"``, ``"no hit"`` (ray misses the DEM), ``"too few"`` (not enough GCPs left
        to refit), ``"outlier"`` (flagged GCP: checked against the final fit).
    grazing_threshold_deg : float
    """

    names: tuple[str, ...]
    reprojection_px: np.ndarray
    ground_error_m: np.ndarray
    ground_error_3d_m: np.ndarray
    range_m: np.ndarray
    grazing_deg: np.ndarray
    m_per_px: np.ndarray
    grazing: np.ndarray
    status: tuple[str, ...]
    grazing_threshold_deg: float


# --------------------------------------------------------------------------- fitting


def check_gcps_in_front(camera: Camera, gcps: Sequence[Gcp], sensor_id: str = "camera") -> None:
    """Refuse GCPs behind the camera as it is posed.

    Raises
    ------
    CalibrationError
        Naming the first GCP with non-positive depth and its angle off the optical axis.
    """
    p = np.array([g.p_enu for g in gcps])
    d = p - camera.position_enu
    depth = d @ camera.R_world_cam[:, 2]
    for k in np.flatnonzero(depth <= 0.0).tolist():
        cosang = depth[k] / max(np.linalg.norm(d[k]), 1e-300)
        ang = math.degrees(math.acos(max(-1.0, min(1.0, float(cosang)))))
        raise CalibrationError(
            f"GCP {gcps[k].name!r} is behind {sensor_id} ({ang:.0f} deg off its optical "
            "axis as the site poses it): check the GCP's coordinates and CRS, or the "
            "camera's azimuth"
        )


def _solve(
    theta0: np.ndarray,
    idx: np.ndarray,
    base: Intrinsics,
    p_enu: np.ndarray,
    uv: np.ndarray,
    loss: str,
    f_scale_px: float,
) -> tuple[np.ndarray, OptimizeResult]:
    def resid(q: np.ndarray) -> np.ndarray:
        theta = theta0.copy()
        theta[idx] = q
        r = _project(theta, base, p_enu) - uv
        return np.where(np.isfinite(r), r, _BEHIND_PX).ravel()

    lo = np.full(len(idx), -np.inf)
    hi = np.full(len(idx), np.inf)
    for j, k in enumerate(idx):
        if k == 1:  # tilt
            lo[j], hi[j] = -90.0, 90.0
        elif k == 3:  # f
            lo[j] = 1e-6 * base.fx
    q0 = np.clip(theta0[idx], lo + 1e-9, hi - 1e-9)
    sol = least_squares(
        resid, q0, bounds=(lo, hi), loss=loss, f_scale=f_scale_px, x_scale="jac", method="trf"
    )
    theta = theta0.copy()
    theta[idx] = sol.x
    return theta, sol


def fit_camera_to_gcps(
    camera: Camera,
    gcps: Sequence[Gcp],
    free: Sequence[str] = DEFAULT_FREE,
    *,
    loss: str = "soft_l1",
    f_scale_px: float = 1.0,
    outlier_px: float | None = None,
    min_outlier_px: float = 3.0,
    reject_outliers: bool = True,
    sensor_id: str = "camera",
) -> GcpFit:
    """Fit the free parameters of ``camera`` to GCPs (see the module notes).

    Parameters
    ----------
    camera : Camera
        Starting camera (the site's pose); it must face the GCPs.
    gcps : sequence of Gcp
        Control points in the site frame.
    free : sequence of str
        Names from :data:`FREE_PARAMETERS`.
    loss : str
        ``least_squares`` loss: ``"soft_l1"``, ``"huber"``, ``"cauchy"``, ``"arctan"``
        or ``"linear"``.
    f_scale_px : float
        Residual scale (px) where the robust loss starts to flatten.
    outlier_px : float, optional
        Fixed outlier threshold; default ``max(min_outlier_px, 4 sigma)``.
    reject_outliers : bool
        Exclude flagged GCPs and refit (they are flagged either way).
    sensor_id : str
        For messages.

    Returns
    -------
    GcpFit

    Raises
    ------
    CalibrationError
        With fewer equations (2 per GCP) than free parameters plus one, GCPs behind the
        camera, or an unusable fitted lens.
    """
    names = tuple(g.name for g in gcps)
    free = tuple(n for n in FREE_PARAMETERS if n in set(free))
    unknown = sorted(set(free) - set(FREE_PARAMETERS))
    if unknown or not free:
        raise CalibrationError(f"bad free parameter list {list(free)}")
    if loss not in ("linear", "soft_l1", "huber", "cauchy", "arctan"):
        raise CalibrationError(f"unknown loss {loss!r}")
    k, p = len(gcps), len(free)
    need = p // 2 + 1
    if k < need:
        raise CalibrationError(
            f"{k} GCP(s) cannot fit {p} parameter(s) ({', '.join(free)}) with a check: "
            f"give at least {need}"
        )
    check_gcps_in_front(camera, gcps, sensor_id)
    base = camera.intrinsics
    p_enu = np.array([g.p_enu for g in gcps], dtype=np.float64)
    uv = np.array([[g.u, g.v] for g in gcps], dtype=np.float64)
    idx = np.array([FREE_PARAMETERS.index(n) for n in free])
    theta0 = _params_of(camera)

    def cost(theta: np.ndarray) -> float:
        r = _project(theta, base, p_enu) - uv
        return float(np.sum(np.minimum(np.nan_to_num(r, nan=_BEHIND_PX) ** 2, _BEHIND_PX)))

    angles = _kabsch_start(camera, gcps)
    if angles is not None and {"yaw", "tilt", "roll"} & set(free):
        trial = theta0.copy()
        for j, name in enumerate(("yaw", "tilt", "roll")):
            if name in free:
                trial[j] = angles[j]
        if cost(trial) < cost(theta0):
            theta0 = trial

    inl = np.ones(k, dtype=bool)
    theta, sol = _solve(theta0, idx, base, p_enu, uv, loss, f_scale_px)
    threshold = float("nan")
    outliers = np.zeros(k, dtype=bool)
    for _ in range(max(1, k)):
        r = _project(theta, base, p_enu) - uv
        norms = np.hypot(r[:, 0], r[:, 1])
        norms = np.where(np.isfinite(norms), norms, np.inf)
        if outlier_px is not None:
            threshold = float(outlier_px)
        else:
            sigma = float(np.median(norms[inl])) / _RAYLEIGH_MEDIAN
            threshold = max(float(min_outlier_px), 4.0 * sigma)
        flagged = norms > threshold
        if not reject_outliers or np.array_equal(flagged, outliers):
            outliers = flagged
            break
        if 2 * int((~flagged).sum()) <= p:
            outliers = flagged
            break  # too few would remain to refit: report, keep the last fit
        outliers = flagged
        inl = ~flagged
        theta, sol = _solve(theta, idx, base, p_enu[inl], uv[inl], loss, f_scale_px)

    fitted = _camera_of(theta, base)
    resid = _project(theta, base, p_enu) - uv
    used = ~outliers if reject_outliers and 2 * int((~outliers).sum()) > p else np.ones(k, bool)
    norms = np.hypot(resid[:, 0], resid[:, 1])
    rmse = float(np.sqrt(np.mean(norms[used] ** 2)))
    dof = 2 * int(used.sum()) - p
    sigmas = {n: float("nan") for n in free}
    jac = getattr(sol, "jac", None)
    if dof > 0 and jac is not None:
        # The Jacobian is of the robust-weighted residuals at the solution; near the
        # inliers' scale it is the plain one. Plain (not robust) variance of unit weight.
        s2 = float(np.sum(resid[used] ** 2)) / dof
        try:
            cov = np.linalg.inv(jac.T @ jac) * s2
            sigmas = {n: float(math.sqrt(max(cov[j, j], 0.0))) for j, n in enumerate(free)}
        except np.linalg.LinAlgError:
            pass
    values = {n: float(theta[FREE_PARAMETERS.index(n)]) for n in free}
    if "yaw" in values:
        values["yaw"] %= 360.0
    notes = []
    if dof <= 0:
        notes.append("no redundancy: as many equations as parameters, residuals prove nothing")
    for j in np.flatnonzero(outliers).tolist():
        notes.append(
            f"GCP {names[j]!r}: residual {norms[j]:.1f} px exceeds {threshold:.1f} px"
            + ("; excluded from the fit" if not used[j] else "; kept (too few GCPs to drop it)")
        )
    if not sol.success:
        notes.append(f"optimiser did not converge: {sol.message}")
    excluded = outliers & ~used
    for arr in (resid, outliers, excluded):
        arr.setflags(write=False)
    return GcpFit(
        camera=fitted,
        free=free,
        values=values,
        sigmas=sigmas,
        names=names,
        residuals_px=resid,
        outliers=outliers,
        excluded=excluded,
        threshold_px=threshold,
        rmse_px=rmse,
        loss=loss,
        converged=bool(sol.success),
        warnings=tuple(notes),
    )


# --------------------------------------------------------------------------- checking


def _ground_check(
    camera: Camera, gcp: Gcp, dem: Dem, max_range_m: float
) -> tuple[float, float, float, float, float, str]:
    """(reproj px, horizontal error m, 3-D error m, range m, grazing deg, status)."""
    u, v, _ = camera.project(gcp.p_enu)
    reproj = float(math.hypot(u[0] - gcp.u, v[0] - gcp.v))
    d = gcp.p_enu - camera.position_enu
    rng = float(np.linalg.norm(d))
    gx, gy = dem.gradient(np.array([gcp.p_enu[0]]), np.array([gcp.p_enu[1]]))
    normal = np.array([-float(np.nan_to_num(gx[0])), -float(np.nan_to_num(gy[0])), 1.0])
    normal /= np.linalg.norm(normal)
    graze = math.degrees(math.asin(min(1.0, abs(float(d @ normal)) / max(rng, 1e-300))))
    if not camera.in_image(gcp.u, gcp.v):
        return reproj, math.nan, math.nan, rng, graze, "off image"
    origin, direction = camera.pixel_to_ray(gcp.u, gcp.v)
    hits = cast_rays(dem, origin, direction, max_range_m, mode="first")
    if int(hits.status[0]) != RayStatus.HIT or hits.counts[0] == 0:
        return reproj, math.nan, math.nan, rng, graze, "no hit"
    p = hits.points[0]
    err_h = float(math.hypot(p[0] - gcp.p_enu[0], p[1] - gcp.p_enu[1]))
    err_3d = float(np.linalg.norm(p - gcp.p_enu))
    return reproj, err_h, err_3d, rng, graze, "ok"


def leave_one_out(
    gcps: Sequence[Gcp],
    fit: GcpFit,
    dem: Dem,
    *,
    grazing_threshold_deg: float = 5.0,
    max_range_m: float = 20_000.0,
) -> LeaveOneOut:
    """Leave-one-out ground check of a fit (see the module notes).

    Parameters
    ----------
    gcps : sequence of Gcp
        The GCPs given to :func:`fit_camera_to_gcps`.
    fit : GcpFit
        The full fit: its free parameters and loss are reused and each refit starts from
        its camera. GCPs it excluded are left out of every refit and checked against
        the final camera, which did not use them.
    dem : Dem
    grazing_threshold_deg : float
        Rays meeting the terrain at less than this are flagged as grazing.
    max_range_m : float
        How far rays are followed.
    """
    k, p = len(gcps), len(fit.free)
    out = np.full((6, k), np.nan)
    status: list[str] = []
    start = fit.camera
    for i in range(k):
        if fit.excluded[i]:
            cam, st = fit.camera, "outlier"
        else:
            rest = [g for j, g in enumerate(gcps) if j != i and not fit.excluded[j]]
            if 2 * len(rest) <= p:
                status.append("too few")
                continue
            sub = fit_camera_to_gcps(
                start, rest, fit.free, loss=fit.loss, outlier_px=math.inf, sensor_id="camera"
            )
            cam, st = sub.camera, "ok"
        reproj, eh, e3, rng, graze, gst = _ground_check(cam, gcps[i], dem, max_range_m)
        f = cam.intrinsics.fx
        out[:, i] = [reproj, eh, e3, rng, graze, rng / f / max(math.sin(math.radians(graze)), 1e-9)]
        status.append(st if gst == "ok" else gst)
    grazing = np.where(np.isfinite(out[4]), out[4] < grazing_threshold_deg, False)
    return LeaveOneOut(
        names=tuple(g.name for g in gcps),
        reprojection_px=out[0],
        ground_error_m=out[1],
        ground_error_3d_m=out[2],
        range_m=out[3],
        grazing_deg=out[4],
        m_per_px=out[5],
        grazing=grazing,
        status=tuple(status),
        grazing_threshold_deg=float(grazing_threshold_deg),
    )
