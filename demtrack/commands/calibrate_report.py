"""The report ``demtrack calibrate --gcps`` prints (text and ``--json``).

Columns of the per-GCP table:

``du px, dv px, |r| px``
    reprojection residual (projected minus observed) under the final fit;
``dh m``
    surveyed height minus the DEM's height at the GCP's east/north;
``ray``
    whether the fitted camera's ray towards the GCP reaches it on the DEM
    (``reaches``, ``passes over``, ``blocked``, ``hole``);
``LOO px, LOO horiz m, LOO vert m``
    leave-one-out: reprojection, and the **horizontal** and **vertical** (hit minus GCP)
    ground errors of its pixel geolocated by the camera fitted without it;
``range m, graze, m/px``
    distance, grazing angle (deg) and ground metres per pixel there;
``flags``
    ``OUTLIER, excluded`` / ``OUTLIER, kept`` (reprojection), ``DEM`` (inconsistent with
    the DEM: the reason follows), ``GRAZING``, ``excluded`` (left out of the fit).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:
    from demtrack.core.camera.gcp_calibration import GcpFit
    from demtrack.core.camera.gcp_dem_check import DemCheck
    from demtrack.core.camera.gcp_loo import LeaveOneOut
    from demtrack.core.site.folder import Sensor

__all__ = ["gcp_json", "print_gcp_report"]

_UNITS = {"yaw": "deg", "tilt": "deg", "roll": "deg", "x": "m", "y": "m", "z": "m"}
_UNITS.update({k: "px" for k in ("f", "fx", "fy", "cx", "cy")})


def _fmt(x: float, spec: str) -> str:
    return format(x, spec) if math.isfinite(x) else "n/a".rjust(len(format(0.0, spec)))


def _flags(i: int, fit: GcpFit, dem: DemCheck, loo: LeaveOneOut) -> list[str]:
    notes = []
    if fit.outliers[i]:
        notes.append("OUTLIER, excluded" if fit.excluded[i] else "OUTLIER, kept")
    if dem.flagged[i]:
        notes.append(f"DEM: {dem.reasons[i]}")
    if loo.grazing[i]:
        notes.append(f"GRAZING (<{loo.grazing_threshold_deg:g} deg)")
    if fit.excluded[i] and not fit.outliers[i]:
        notes.append("excluded")
    if loo.status[i] not in ("ok", "outlier", "excluded"):
        notes.append(f"LOO {loo.status[i]}")
    return notes


def _rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x**2))) if x.size else math.nan


def _loo_summary(fit: GcpFit, dem: DemCheck, loo: LeaveOneOut) -> dict[str, Any]:
    ok = np.array([s == "ok" for s in loo.status])
    clean = ok & ~dem.flagged & ~fit.excluded
    out: dict[str, Any] = {}
    for key, mask in (("kept_dem_consistent", clean), ("all", np.isfinite(loo.ground_error_m))):
        h, v = loo.ground_error_m[mask], loo.vertical_error_m[mask]
        out[key] = {
            "n": int(np.isfinite(h).sum()),
            "horizontal_rms_m": _rms(h),
            "horizontal_max_m": float(np.nanmax(h)) if np.isfinite(h).any() else math.nan,
            "vertical_rms_m": _rms(v),
        }
    return out


def print_gcp_report(
    sensor: Sensor, fit: GcpFit, dem: DemCheck, loo: LeaveOneOut, where: str
) -> None:
    """Print the text report (see the module notes)."""
    k = len(fit.names)
    used = int((~fit.excluded).sum())
    print(
        f"{sensor.id} ({sensor.name}): fitted {','.join(fit.free)} to {k} GCPs "
        f"({used} kept), loss {fit.loss} (scale {fit.f_scale_px:g} px)"
    )
    print(
        f"  RMSE {fit.rmse_px:.3f} px over the {used} GCPs kept in the fit; "
        f"{fit.rmse_all_px:.3f} px over all {k} GCPs"
    )
    print(f"  {'param':<6}{'value':>14}{'sigma':>12}  {'unit':<5}{'start':>14}  bound / prior")
    for name in fit.free:
        extra = []
        if name in fit.bounds:
            extra.append(f"bound {fit.bounds[name][0]:g}..{fit.bounds[name][1]:g}")
        if name in fit.priors:
            extra.append(f"prior {fit.priors[name][0]:g} +- {fit.priors[name][1]:g}")
        print(
            f"  {name:<6}{fit.values[name]:14.5f}{_fmt(fit.sigmas[name], '12.5f')}  "
            f"{_UNITS.get(name, ''):<5}{fit.start_values[name]:14.5f}  {'; '.join(extra)}".rstrip()
        )
    print(
        f"  {'GCP':<14}{'du px':>8}{'dv px':>8}{'|r| px':>8}{'dh m':>8}  {'ray':<12}"
        f"{'LOO px':>8}{'LOO horiz m':>12}{'LOO vert m':>11}{'range m':>9}{'graze':>7}"
        f"{'m/px':>7}  flags"
    )
    for i, name in enumerate(fit.names):
        du, dv = fit.residuals_px[i]
        print(
            f"  {name[:13]:<14}{du:+8.2f}{dv:+8.2f}{math.hypot(du, dv):8.2f}"
            f"{_fmt(float(dem.dh_m[i]), '+8.2f')}  {dem.ray[i][:11]:<12}"
            f"{_fmt(loo.reprojection_px[i], '8.2f')}{_fmt(loo.ground_error_m[i], '12.2f')}"
            f"{_fmt(loo.vertical_error_m[i], '+11.2f')}{_fmt(loo.range_m[i], '9.1f')}"
            f"{_fmt(loo.grazing_deg[i], '7.1f')}{_fmt(loo.m_per_px[i], '7.2f')}  "
            f"{'; '.join(_flags(i, fit, dem, loo))}".rstrip()
        )
    s = _loo_summary(fit, dem, loo)
    for key, label in (("kept_dem_consistent", "kept, DEM-consistent"), ("all", "all")):
        e = s[key]
        if e["n"]:
            print(
                f"  leave-one-out ground error over {e['n']} GCPs ({label}): horizontal RMS "
                f"{e['horizontal_rms_m']:.2f} m, max {e['horizontal_max_m']:.2f} m; "
                f"vertical RMS {e['vertical_rms_m']:.2f} m"
            )
    n_out, n_dem = int(fit.outliers.sum()), int(dem.flagged.sum())
    print(
        f"  flagged: {n_out} reprojection outlier(s) (> {fit.threshold_px:.2f} px), "
        f"{n_dem} inconsistent with the DEM"
    )
    for w in fit.warnings:
        print(f"  warning: {w}")
    print(f"  {where}")


def gcp_json(
    sensor: Sensor, fit: GcpFit, dem: DemCheck, loo: LeaveOneOut, written: bool
) -> dict[str, Any]:
    """The ``--json`` document."""

    def num(x: float) -> float | None:
        return float(x) if math.isfinite(x) else None

    cov = [[num(float(c)) for c in row] for row in fit.covariance]
    summary = {
        k: {kk: (num(vv) if isinstance(vv, float) else vv) for kk, vv in v.items()}
        for k, v in _loo_summary(fit, dem, loo).items()
    }
    return {
        "sensor": sensor.id,
        "free": list(fit.free),
        "values": fit.values,
        "sigmas": {k: num(v) for k, v in fit.sigmas.items()},
        "start_values": fit.start_values,
        "covariance": cov,
        "bounds": {k: list(v) for k, v in fit.bounds.items()},
        "priors": {k: list(v) for k, v in fit.priors.items()},
        "rmse_px": num(fit.rmse_px),
        "rmse_kept_px": num(fit.rmse_px),
        "rmse_all_px": fit.rmse_all_px,
        "n_kept": int((~fit.excluded).sum()),
        "threshold_px": fit.threshold_px,
        "loss": fit.loss,
        "f_scale_px": fit.f_scale_px,
        "converged": fit.converged,
        "written": written,
        "leave_one_out": summary,
        "gcps": [
            {
                "name": name,
                "residual_px": [float(x) for x in fit.residuals_px[i]],
                "residual_norm_px": float(fit.residual_norms_px[i]),
                "outlier": bool(fit.outliers[i]),
                "excluded": bool(fit.excluded[i]),
                "dem_z_m": num(float(dem.dem_z_m[i])),
                "dh_m": num(float(dem.dh_m[i])),
                "ray": dem.ray[i],
                "ray_miss_m": num(float(dem.ray_miss_m[i])),
                "dem_flagged": bool(dem.flagged[i]),
                "dem_reason": dem.reasons[i],
                "loo_reprojection_px": num(loo.reprojection_px[i]),
                "loo_horizontal_error_m": num(loo.ground_error_m[i]),
                "loo_ground_error_m": num(loo.ground_error_m[i]),
                "loo_vertical_error_m": num(loo.vertical_error_m[i]),
                "loo_ground_error_3d_m": num(loo.ground_error_3d_m[i]),
                "range_m": num(loo.range_m[i]),
                "grazing_deg": num(loo.grazing_deg[i]),
                "m_per_px": num(loo.m_per_px[i]),
                "grazing": bool(loo.grazing[i]),
                "loo_status": loo.status[i],
            }
            for i, name in enumerate(fit.names)
        ],
        "warnings": list(fit.warnings),
    }
