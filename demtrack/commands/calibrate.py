"""``demtrack calibrate-yaw``: a pan-tilt head's yaw from its landmark pan readings."""

from __future__ import annotations

import argparse
import json

from demtrack.core.site import load_site

from .common import add_site_argument

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
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


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``calibrate-yaw`` command."""
    p = sub.add_parser("calibrate-yaw", help="estimate a pan-tilt head's yaw from landmarks")
    add_site_argument(p)
    p.add_argument("--sensor", required=True, metavar="ID")
    p.add_argument(
        "--threshold",
        type=float,
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
