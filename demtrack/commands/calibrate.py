"""``demtrack calibrate`` (GCP fit) and ``demtrack calibrate-yaw`` (pan-tilt landmarks).

``calibrate --gcps`` fits a camera to ground control points and writes it back into the
site; ``calibrate-yaw`` estimates a pan-tilt head's yaw from landmark pan readings.
"""

from __future__ import annotations

import argparse
import json
import math
from typing import TYPE_CHECKING

from .choices import DEFAULT_FREE, FREE_PARAMETERS
from .common import add_site_argument, non_negative, positive

if TYPE_CHECKING:
    from demtrack.core.camera.gcp_calibration import GcpFit
    from demtrack.core.camera.gcp_loo import LeaveOneOut
    from demtrack.core.site.folder import Sensor, Site

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    from demtrack.core.site.folder import load_site

    site = load_site(args.site)
    sensor = site.sensor(args.sensor)
    cal = sensor.head.calibrate(args.threshold, reject_outliers=not args.keep_outliers)
    marks = sensor.head.landmarks
    if args.json:
        print(
            json.dumps(
                {
                    "sensor": sensor.id,
                    "yaw_deg": cal.yaw_deg,
                    "rms_deg": cal.rms_deg,
                    "site_yaw_deg": sensor.head.mount_yaw_deg,
                    "landmarks": [
                        {
                            "name": m.name,
                            "pan_deg": m.pan_deg,
                            "bearing_deg": float(b),
                            "distance_m": float(d),
                            "residual_deg": float(r),
                            "outlier": bool(o),
                        }
                        for m, b, d, r, o in zip(
                            marks,
                            cal.bearings_deg,
                            cal.distances_m,
                            cal.residuals_deg,
                            cal.outliers,
                            strict=True,
                        )
                    ],
                    "warnings": list(cal.warnings),
                },
                indent=2,
            )
        )
        return 0
    print(
        f"{sensor.id} ({sensor.name}): mount yaw {cal.yaw_deg:.4f} deg from "
        f"{len(marks)} landmarks (circular mean), rms residual {cal.rms_deg:.4f} deg"
    )
    print(f"  site.json has {sensor.head.mount_yaw_deg:.4f} deg")
    print(f"  {'landmark':<28}{'pan':>10}{'bearing':>10}{'dist m':>9}{'resid':>9}")
    for m, b, d, r, o in zip(
        marks, cal.bearings_deg, cal.distances_m, cal.residuals_deg, cal.outliers, strict=True
    ):
        flag = "  OUTLIER" if o else ""
        print(f"  {m.name:<28}{m.pan_deg:10.3f}{b:10.3f}{d:9.1f}{r:+9.3f}{flag}")
    for w in cal.warnings:
        print(f"  warning: {w}")
    return 0


def _fitted_sensor(site: Site, sensor: Sensor, fit: GcpFit) -> Sensor:
    """The sensor posed as the fit says: yaw = mount yaw + pan reading, tilt, roll."""
    from demtrack.core.camera.pantilt import PanTiltHead
    from demtrack.core.site.folder import Sensor

    cam = fit.camera
    az, tilt, roll = cam.azimuth_tilt_roll_deg()
    head = PanTiltHead(cam.position_enu, az - sensor.pan_deg, cam.intrinsics, sensor.head.landmarks)
    return Sensor(sensor.id, sensor.name, head, sensor.pan_deg, tilt, sensor.image_path, roll)


def _fmt(x: float, spec: str) -> str:
    return format(x, spec) if math.isfinite(x) else "n/a".rjust(len(format(0.0, spec)))


def _print_gcp_report(sensor: Sensor, fit: GcpFit, loo: LeaveOneOut, start) -> None:
    import numpy as np

    k = len(fit.names)
    used = int((~fit.excluded).sum())
    print(
        f"{sensor.id} ({sensor.name}): fitted {','.join(fit.free)} to {k} GCPs "
        f"({used} used), loss {fit.loss}; RMSE {fit.rmse_px:.2f} px over the GCPs used"
    )
    a0 = dict(zip(("yaw", "tilt", "roll"), start.azimuth_tilt_roll_deg(), strict=True))
    i0 = start.intrinsics
    before = {"f": i0.fx, "cx": i0.cx, "cy": i0.cy, "k1": i0.k1, "k2": i0.k2}
    before.update(a0)
    before.update(zip(("x", "y", "z"), start.position_enu, strict=True))
    for name in fit.free:
        print(
            f"  {name:<5} {fit.values[name]:12.5f}  +- {_fmt(fit.sigmas[name], '.5f')}"
            f"   (was {before[name]:.5f})"
        )
    print(
        f"  {'GCP':<20}{'du px':>8}{'dv px':>8}{'|r| px':>8}{'LOO px':>8}{'LOO m':>8}"
        f"{'range m':>9}{'graze':>7}{'m/px':>7}  note"
    )
    for i, name in enumerate(fit.names):
        du, dv = fit.residuals_px[i]
        notes = []
        if fit.outliers[i]:
            notes.append("OUTLIER, excluded" if fit.excluded[i] else "OUTLIER, kept")
        if loo.grazing[i]:
            notes.append(f"GRAZING (<{loo.grazing_threshold_deg:g} deg)")
        if loo.status[i] not in ("ok", "outlier"):
            notes.append(loo.status[i])
        print(
            f"  {name[:19]:<20}{du:+8.2f}{dv:+8.2f}{math.hypot(du, dv):8.2f}"
            f"{_fmt(loo.reprojection_px[i], '8.2f')}{_fmt(loo.ground_error_m[i], '8.2f')}"
            f"{_fmt(loo.range_m[i], '9.1f')}{_fmt(loo.grazing_deg[i], '7.1f')}"
            f"{_fmt(loo.m_per_px[i], '7.2f')}  {'; '.join(notes)}"
        )
    ok = np.array([s == "ok" for s in loo.status])
    if ok.any():
        errs = loo.ground_error_m[ok]
        errs = errs[np.isfinite(errs)]
        if errs.size:
            print(
                f"  leave-one-out ground error: RMS {np.sqrt(np.mean(errs**2)):.2f} m, "
                f"max {errs.max():.2f} m over {errs.size} GCPs"
            )
    print(f"  outlier threshold {fit.threshold_px:.2f} px")
    for w in fit.warnings:
        print(f"  warning: {w}")


def _gcp_json(sensor: Sensor, fit: GcpFit, loo: LeaveOneOut, written: bool) -> dict:
    def num(x: float) -> float | None:
        return float(x) if math.isfinite(x) else None

    return {
        "sensor": sensor.id,
        "free": list(fit.free),
        "values": fit.values,
        "sigmas": {k: num(v) for k, v in fit.sigmas.items()},
        "rmse_px": fit.rmse_px,
        "threshold_px": fit.threshold_px,
        "loss": fit.loss,
        "converged": fit.converged,
        "written": written,
        "gcps": [
            {
                "name": name,
                "residual_px": [float(x) for x in fit.residuals_px[i]],
                "outlier": bool(fit.outliers[i]),
                "excluded": bool(fit.excluded[i]),
                "loo_reprojection_px": num(loo.reprojection_px[i]),
                "loo_ground_error_m": num(loo.ground_error_m[i]),
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


def _run_gcps(args: argparse.Namespace) -> int:
    from demtrack.core.camera.gcp_calibration import fit_camera_to_gcps, parse_free
    from demtrack.core.camera.gcp_loo import leave_one_out
    from demtrack.core.camera.gcp_io import gcps_to_local, read_gcp_csv
    from demtrack.core.site.folder import load_site
    from demtrack.core.site.update import read_manifest, write_manifest

    site = load_site(args.site)
    sensor = site.sensor(args.sensor)
    free = parse_free(args.free)
    gcps = gcps_to_local(
        read_gcp_csv(args.gcps),
        site.frame,
        crs=args.gcp_crs,
        vertical=args.gcp_vertical,
        geoid_undulation_m=site.geoid_undulation_m,
    )
    start = sensor.camera
    fit = fit_camera_to_gcps(
        start,
        gcps,
        free,
        loss=args.loss,
        f_scale_px=args.f_scale,
        outlier_px=args.outlier_px,
        reject_outliers=not args.keep_outliers,
        sensor_id=f"camera {sensor.id!r}",
    )
    loo = leave_one_out(gcps, fit, site.dem, grazing_threshold_deg=args.grazing_deg)
    written = False
    if not args.dry_run:
        fitted = _fitted_sensor(site, sensor, fit)
        doc = read_manifest(args.site)
        entries = doc.get("sensors", [])
        for k, entry in enumerate(entries):
            if isinstance(entry, dict) and entry.get("id") == sensor.id:
                new = dict(entry)
                new.update(fitted.to_dict(site.root))
                if fitted.roll_deg == 0.0:
                    new.pop("roll_deg", None)
                entries[k] = new
        write_manifest(args.site, doc)
        written = True
    if args.json:
        print(json.dumps(_gcp_json(sensor, fit, loo, written), indent=2))
        return 0
    _print_gcp_report(sensor, fit, loo, start)
    where = args.site / "site.json"
    print(f"  {'written to ' + str(where) if written else 'dry run: site.json not changed'}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``calibrate`` (GCP) and ``calibrate-yaw`` commands."""
    p = sub.add_parser("calibrate", help="fit a camera to ground control points")
    add_site_argument(p)
    p.add_argument("--sensor", required=True, metavar="ID")
    p.add_argument("--gcps", required=True, metavar="FILE.csv", help="name,u,v,x,y,z (see docs)")
    p.add_argument("--gcp-crs", metavar="CRS", help="CRS of x,y,z ('local' = site frame)")
    p.add_argument("--gcp-vertical", choices=("ellipsoidal", "orthometric"), help="heights' datum")
    p.add_argument(
        "--free",
        default=",".join(DEFAULT_FREE),
        metavar="LIST",
        help=f"parameters to fit, from {','.join(FREE_PARAMETERS)} (default yaw,tilt,roll)",
    )
    p.add_argument(
        "--loss",
        default="soft_l1",
        choices=("soft_l1", "huber", "cauchy", "arctan", "linear"),
        help="robust loss (default soft_l1)",
    )
    p.add_argument("--f-scale", type=positive, default=1.0, metavar="PX", help="loss scale")
    p.add_argument(
        "--outlier-px", type=positive, metavar="PX", help="outlier threshold (default auto)"
    )
    p.add_argument("--keep-outliers", action="store_true", help="flag but do not exclude")
    p.add_argument(
        "--grazing-deg", type=non_negative, default=5.0, metavar="DEG", help="grazing-ray threshold"
    )
    p.add_argument("--dry-run", action="store_true", help="report only; leave site.json")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_run_gcps)

    p = sub.add_parser("calibrate-yaw", help="estimate a pan-tilt head's yaw from landmarks")
    add_site_argument(p)
    p.add_argument("--sensor", required=True, metavar="ID")
    p.add_argument(
        "--threshold",
        type=positive,
        default=1.0,
        metavar="DEG",
        help="residual above which a landmark is an outlier (default 1 deg)",
    )
    p.add_argument(
        "--keep-outliers",
        action="store_true",
        help="plain circular mean over every landmark (the paper's estimate)",
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_run)
