"""Camera calibration from ground control points (GCPs) by robust least squares.

A GCP is a pixel ``(u, v)`` whose world position is known (surveyed, or read off an
orthophoto and the DEM). The fit adjusts the chosen camera parameters (any of
:data:`~demtrack.core.camera.gcp_model.FREE_PARAMETERS`: orientation, position, focal
lengths tied or apart, principal point, ``k1, k2, k3, p1, p2``) so that the GCPs project
onto their pixels, within optional bounds and under optional priors (extra residuals).

Cost: the reprojection residuals in pixels (and the prior residuals) under a robust loss
(``scipy.optimize.least_squares``, trust-region reflective; ``soft_l1`` by default with a
scale of 1 px), which bounds a blunder's pull. Outliers are then *flagged*, not silently
down-weighted: a GCP whose residual exceeds the threshold (``outlier_px``, default
``max(3 px, 4 sigma)`` with ``sigma`` the per-axis noise estimated robustly from the
median residual, ``median |r| / 1.1774`` for a 2-D Gaussian) is excluded and the fit
repeated until the flagged set is stable. GCPs the caller excludes (``exclude``, e.g. those
inconsistent with the DEM) are left out from the start.

Covariance: ``C = s^2 (J^T J)^-1`` with ``J`` the Jacobian of the plain (not robust)
residual vector of the GCPs used plus the priors at the solution (central differences), and
``s^2 = sum(r^2) / (m - p)`` the residual variance of unit weight (``m`` residuals, ``p``
free parameters). Each free parameter's 1-sigma is ``sqrt(C_jj)`` in its own unit.

Orientation start: the Kabsch/Wahba rotation that best aligns the GCPs' pixel rays with
their directions from the camera, taken when it fits better than the site's pose, so a
start several tens of degrees off still converges.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from scipy.optimize import OptimizeResult, least_squares

from ..errors import CalibrationError, CameraError
from .gcp_io import Gcp
from .gcp_model import (
    DEFAULT_FREE,
    FREE_PARAMETERS,
    THETA,
    FitModel,
    camera_of,
    params_of,
    parse_free,
    project,
)
from .pinhole import Camera

__all__ = [
    "DEFAULT_FREE",
    "FREE_PARAMETERS",
    "LOSSES",
    "GcpFit",
    "check_gcps_in_front",
    "fit_camera_to_gcps",
    "parse_free",
]

#: Robust losses offered (``scipy.optimize.least_squares``).
LOSSES = ("linear", "soft_l1", "huber", "cauchy", "arctan")
_BEHIND_PX = 1e4  # residual given to a GCP behind the camera during the search
_RAYLEIGH_MEDIAN = math.sqrt(2.0 * math.log(2.0))  # median of |r| / sigma for 2-D noise


def _value_of(theta: np.ndarray, name: str) -> float:
    return float(theta[THETA.index("fx" if name == "f" else name)])


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
        Fitted value of each free parameter (deg, px, m or unitless).
    sigmas : dict of str to float
        1-sigma of each free parameter from the covariance (NaN with no redundancy).
    covariance : ndarray, shape (p, p)
        Parameter covariance in ``free`` order (NaN with no redundancy).
    start_values : dict of str to float
        Each free parameter's starting value.
    names : tuple of str
        GCP names, in input order.
    residuals_px : ndarray, shape (k, 2)
        Projected minus observed pixel for every GCP (outliers included).
    outliers : ndarray of bool, shape (k,)
        GCPs whose residual exceeds the threshold.
    excluded : ndarray of bool, shape (k,)
        GCPs left out of the final fit: flagged outliers (unless too few GCPs would
        remain or rejection was off) and those the caller excluded.
    threshold_px : float
        The residual magnitude above which a GCP is flagged.
    rmse_px : float
        Root mean square of ``|residual|`` over the GCPs used (kept) in the final fit.
    rmse_all_px : float
        The same over every GCP, excluded ones included.
    loss : str
        The robust loss used.
    f_scale_px : float
    converged : bool
        Whether the optimiser reported convergence.
    warnings : tuple of str
    """

    camera: Camera
    free: tuple[str, ...]
    values: dict[str, float]
    sigmas: dict[str, float]
    covariance: np.ndarray
    start_values: dict[str, float]
    names: tuple[str, ...]
    residuals_px: np.ndarray
    outliers: np.ndarray
    excluded: np.ndarray
    threshold_px: float
    rmse_px: float
    rmse_all_px: float
    loss: str
    f_scale_px: float
    converged: bool
    warnings: tuple[str, ...] = field(default=())
    bounds: Mapping[str, tuple[float, float]] = field(default_factory=dict)
    priors: Mapping[str, tuple[float, float]] = field(default_factory=dict)

    @property
    def residual_norms_px(self) -> np.ndarray:
        """``|residual|`` per GCP (px), shape (k,)."""
        return np.hypot(self.residuals_px[:, 0], self.residuals_px[:, 1])


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


def _residuals(
    theta: np.ndarray, model: FitModel, p_enu: np.ndarray, uv: np.ndarray, pixel_sigma_px: float
) -> np.ndarray:
    r = project(theta, p_enu, model.fy_ratio, model.k4) - uv
    r = np.where(np.isfinite(r), r, _BEHIND_PX).ravel()
    if model.n_priors:
        r = np.concatenate([r, model.prior_residuals(theta, pixel_sigma_px)])
    return r


def _solve(
    theta0: np.ndarray,
    model: FitModel,
    p_enu: np.ndarray,
    uv: np.ndarray,
    loss: str,
    f_scale_px: float,
    pixel_sigma_px: float,
) -> tuple[np.ndarray, OptimizeResult]:
    idx = model.index

    def resid(q: np.ndarray) -> np.ndarray:
        theta = theta0.copy()
        theta[idx] = q
        return _residuals(theta, model, p_enu, uv, pixel_sigma_px)

    width = np.where(np.isfinite(model.hi - model.lo), model.hi - model.lo, 1.0)
    pad = 1e-9 * np.maximum(width, 1e-300)
    q0 = np.clip(theta0[idx], model.lo + pad, model.hi - pad)
    sol = least_squares(
        resid,
        q0,
        bounds=(model.lo, model.hi),
        loss=loss,
        f_scale=f_scale_px,
        x_scale="jac",
        method="trf",
        xtol=1e-12,
        ftol=1e-12,
        gtol=1e-12,
        max_nfev=200 * (len(idx) + 1),
    )
    theta = theta0.copy()
    theta[idx] = sol.x
    return theta, sol


def _covariance(
    theta: np.ndarray,
    model: FitModel,
    p_enu: np.ndarray,
    uv: np.ndarray,
    pixel_sigma_px: float,
) -> tuple[np.ndarray, int]:
    """``s^2 (J^T J)^-1`` of the plain residuals at ``theta``, and the redundancy."""
    p = len(model.index)
    r0 = _residuals(theta, model, p_enu, uv, pixel_sigma_px)
    dof = r0.size - p
    cov = np.full((p, p), np.nan)
    if dof <= 0:
        return cov, dof
    jac = np.empty((r0.size, p))
    for j, k in enumerate(model.index):
        h = 1e-6 * max(abs(float(theta[k])), 1.0 if k < 7 or k >= 12 else 1e-2)
        tp, tm = theta.copy(), theta.copy()
        tp[k] += h
        tm[k] -= h
        jac[:, j] = (
            _residuals(tp, model, p_enu, uv, pixel_sigma_px)
            - _residuals(tm, model, p_enu, uv, pixel_sigma_px)
        ) / (2.0 * h)
    s2 = float(r0 @ r0) / dof
    try:
        cov = np.linalg.inv(jac.T @ jac) * s2
    except np.linalg.LinAlgError:
        pass
    return cov, dof


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
    bounds: Mapping[str, tuple[float, float]] | None = None,
    priors: Mapping[str, tuple[float, float]] | None = None,
    pixel_sigma_px: float = 1.0,
    exclude: np.ndarray | None = None,
    kabsch: bool = True,
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
        One of :data:`LOSSES`.
    f_scale_px : float
        Residual scale (px) where the robust loss starts to flatten.
    outlier_px : float, optional
        Fixed outlier threshold; default ``max(min_outlier_px, 4 sigma)``.
    reject_outliers : bool
        Exclude flagged GCPs and refit (they are flagged either way).
    bounds : mapping of str to (float, float), optional
        ``(lo, hi)`` per free parameter, in its unit; the start must lie within.
    priors : mapping of str to (float, float), optional
        ``(value, sigma)`` per free parameter.
    pixel_sigma_px : float
        Pixel noise a prior's sigma is weighed against.
    exclude : ndarray of bool, shape (k,), optional
        GCPs to leave out of the fit (they are still reported).
    kabsch : bool
        Try the Kabsch orientation start.
    sensor_id : str
        For messages.

    Returns
    -------
    GcpFit

    Raises
    ------
    CalibrationError
        With fewer equations (2 per GCP plus the priors) than free parameters plus one,
        GCPs behind the camera, a bound that excludes its start, or an unusable fitted lens.
    """
    names = tuple(g.name for g in gcps)
    if loss not in LOSSES:
        raise CalibrationError(f"unknown loss {loss!r}; choose from {','.join(LOSSES)}")
    theta0 = params_of(camera)
    model = replace(FitModel.build(tuple(free), theta0, bounds, priors), k4=camera.intrinsics.k4)
    free = model.free
    k, p = len(gcps), len(free)
    given_out = np.zeros(k, bool) if exclude is None else np.asarray(exclude, bool).copy()
    n_use = k - int(given_out.sum())
    need = max(0, (p - model.n_priors) // 2 + 1)
    if n_use < need:
        raise CalibrationError(
            f"{n_use} GCP(s) cannot fit {p} parameter(s) ({', '.join(free)}) with a check: "
            f"give at least {need}"
        )
    check_gcps_in_front(camera, gcps, sensor_id)
    start_values = {n: _value_of(theta0, n) for n in free}
    p_enu = np.array([g.p_enu for g in gcps], dtype=np.float64)
    uv = np.array([[g.u, g.v] for g in gcps], dtype=np.float64)

    def cost(theta: np.ndarray) -> float:
        r = project(theta, p_enu[~given_out], model.fy_ratio, model.k4) - uv[~given_out]
        return float(np.sum(np.minimum(np.nan_to_num(r, nan=_BEHIND_PX) ** 2, _BEHIND_PX)))

    angles = _kabsch_start(camera, [g for g, o in zip(gcps, given_out, strict=True) if not o])
    if kabsch and angles is not None and {"yaw", "tilt", "roll"} & set(free):
        trial = theta0.copy()
        for j, name in enumerate(("yaw", "tilt", "roll")):
            if name in free:
                trial[j] = angles[j]
        inside = all(model.lo[i] <= trial[model.index[i]] <= model.hi[i] for i in range(p))
        if inside and cost(trial) < cost(theta0):
            theta0 = trial

    def solve(mask: np.ndarray, start: np.ndarray) -> tuple[np.ndarray, OptimizeResult]:
        return _solve(start, model, p_enu[mask], uv[mask], loss, f_scale_px, pixel_sigma_px)

    inl = ~given_out
    theta, sol = solve(inl, theta0)
    threshold = float("nan")
    outliers = np.zeros(k, dtype=bool)
    for _ in range(max(1, k)):
        r = project(theta, p_enu, model.fy_ratio, model.k4) - uv
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
        if 2 * int((~flagged & ~given_out).sum()) + model.n_priors <= p:
            outliers = flagged
            break  # too few would remain to refit: report, keep the last fit
        outliers = flagged
        inl = ~flagged & ~given_out
        theta, sol = solve(inl, theta)

    fitted = camera_of(theta, camera.intrinsics, model.fy_ratio)
    resid = project(theta, p_enu, model.fy_ratio, model.k4) - uv
    drop_outliers = reject_outliers and 2 * int((~outliers & ~given_out).sum()) + model.n_priors > p
    used = ~given_out & (~outliers if drop_outliers else True)
    norms = np.hypot(resid[:, 0], resid[:, 1])
    rmse = float(np.sqrt(np.mean(norms[used] ** 2))) if used.any() else math.nan
    rmse_all = float(np.sqrt(np.mean(norms**2)))
    cov, dof = _covariance(theta, model, p_enu[used], uv[used], pixel_sigma_px)
    sigmas = {n: float(math.sqrt(max(cov[j, j], 0.0))) for j, n in enumerate(free)}
    values = {n: _value_of(theta, n) for n in free}
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
    for j, n in enumerate(free):
        q = float(theta[model.index[j]])
        on_lo = np.isfinite(model.lo[j]) and abs(q - model.lo[j]) <= 1e-7 * (1 + abs(q))
        on_hi = np.isfinite(model.hi[j]) and abs(q - model.hi[j]) <= 1e-7 * (1 + abs(q))
        if on_lo or on_hi:
            notes.append(f"{n} ended on its bound ({values[n]:g}): its sigma is not meaningful")
    if not sol.success:
        notes.append(f"optimiser did not converge: {sol.message}")
    excluded = ~used
    for arr in (resid, outliers, excluded, cov):
        arr.setflags(write=False)
    return GcpFit(
        camera=fitted,
        free=free,
        values=values,
        sigmas=sigmas,
        covariance=cov,
        start_values=start_values,
        names=names,
        residuals_px=resid,
        outliers=outliers,
        excluded=excluded,
        threshold_px=threshold,
        rmse_px=rmse,
        rmse_all_px=rmse_all,
        loss=loss,
        f_scale_px=float(f_scale_px),
        converged=bool(sol.success),
        warnings=tuple(notes),
        bounds=dict(bounds or {}),
        priors=dict(priors or {}),
    )
