"""``demtrack calibrate`` (GCP fit) and ``demtrack calibrate-yaw`` (pan-tilt landmarks).

``calibrate --gcps`` fits a camera to ground control points and writes it back into the
site (atomically; the report is in ``calibrate_report``); ``convert-gcps`` turns ImGRAFT or
CSV GCP files into demtrack's GCP CSV; ``calibrate-yaw`` estimates a pan-tilt head's yaw
from landmark pan readings.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

from .choices import DEFAULT_FREE, FREE_PARAMETERS, GCP_FORMATS, GCP_LOSSES
from .common import add_site_argument, non_negative, positive

if TYPE_CHECKING:
    from demtrack.core.camera.gcp_calibration import GcpFit
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
    import dataclasses

    from demtrack.core.camera.pantilt import PanTiltHead

    cam = fit.camera
    az, tilt, roll = cam.azimuth_tilt_roll_deg()
    head = PanTiltHead(cam.position_enu, az - sensor.pan_deg, cam.intrinsics, sensor.head.landmarks)
    # replace, not a new Sensor: the PTZ fields (active, zoom, latency, slew limits) stay.
    return dataclasses.replace(sensor, head=head, tilt_deg=tilt, roll_deg=roll)


def _prior_position(args: argparse.Namespace, site: Site) -> dict[str, tuple[float, float]]:
    """``--prior-position X,Y,Z,SIGMA`` (in ``--prior-crs``) as priors on x, y, z (site frame)."""
    from demtrack.core.errors import CalibrationError, DemtrackError

    text = args.prior_position
    if text is None:
        if args.prior_crs is not None:
            raise CalibrationError("--prior-crs is given without --prior-position")
        return {}
    try:
        vals = [float(t) for t in text.split(",")]
    except ValueError:
        vals = []
    if len(vals) != 4 or not all(math.isfinite(v) for v in vals) or not vals[3] > 0:
        raise CalibrationError(
            f"--prior-position {text!r} is malformed: write X,Y,Z,SIGMA (SIGMA > 0, m)"
        )
    crs = args.prior_crs or "local"
    if crs.strip().lower() == "local":
        xyz = vals[:3]
    else:
        if args.prior_vertical is None:
            raise CalibrationError(
                "--prior-position in a CRS needs --prior-vertical ellipsoidal|orthometric"
            )
        n = site.geoid_undulation_m if args.prior_vertical == "orthometric" else 0.0
        try:
            xyz = [
                float(v) for v in site.frame.to_enu_from_crs(*vals[:3], crs, geoid_undulation_m=n)
            ]
        except DemtrackError as exc:
            raise CalibrationError(f"--prior-position: {exc}") from None
    return {n: (v, vals[3]) for n, v in zip(("x", "y", "z"), xyz, strict=True)}


def _run_gcps(args: argparse.Namespace) -> int:
    import numpy as np

    from demtrack.core.camera.gcp_calibration import fit_camera_to_gcps
    from demtrack.core.camera.gcp_convert import read_gcps
    from demtrack.core.camera.gcp_dem_check import check_gcps_inside_dem, check_gcps_on_dem
    from demtrack.core.camera.gcp_io import gcps_to_local
    from demtrack.core.camera.gcp_loo import leave_one_out
    from demtrack.core.camera.gcp_model import parse_bounds, parse_free, parse_priors
    from demtrack.core.errors import CalibrationError
    from demtrack.core.site.folder import load_site
    from demtrack.core.site.update import read_manifest, write_manifest

    from .calibrate_report import gcp_json, print_gcp_report

    free = parse_free(args.free)
    bounds = parse_bounds(args.bound or [])
    priors = parse_priors(args.prior or [])
    site = load_site(args.site)
    for name, value in _prior_position(args, site).items():
        if name in priors:
            raise CalibrationError(f"--prior {name} and --prior-position both give {name}")
        priors[name] = value
    sensor = site.sensor(args.sensor)
    gcps = gcps_to_local(
        read_gcps(args.gcps, args.gcp_format),
        site.frame,
        crs=args.gcp_crs,
        vertical=args.gcp_vertical,
        geoid_undulation_m=site.geoid_undulation_m,
    )
    check_gcps_inside_dem(gcps, site.dem)
    start = sensor.camera
    options = dict(
        loss=args.loss,
        f_scale_px=args.f_scale,
        outlier_px=args.outlier_px,
        reject_outliers=not args.keep_outliers,
        bounds=bounds,
        priors=priors,
        pixel_sigma_px=args.pixel_sigma,
        sensor_id=f"camera {sensor.id!r}",
    )
    fit = fit_camera_to_gcps(start, gcps, free, **options)  # type: ignore[arg-type]
    dem = check_gcps_on_dem(fit.camera, gcps, site.dem, height_tol_m=args.height_tol)
    if args.exclude_dem_flagged and dem.flagged.any():
        flagged = np.array(dem.flagged)
        fit = fit_camera_to_gcps(start, gcps, free, exclude=flagged, **options)  # type: ignore[arg-type]
        dem = check_gcps_on_dem(fit.camera, gcps, site.dem, height_tol_m=args.height_tol)
    loo = leave_one_out(
        gcps, fit, site.dem, grazing_threshold_deg=args.grazing_deg, pixel_sigma_px=args.pixel_sigma
    )
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
        write_manifest(args.site, doc)  # temporary file + os.replace
        written = True
    if args.json:
        print(json.dumps(gcp_json(sensor, fit, dem, loo, written), indent=2))
        return 0
    where = args.site / "site.json"
    print_gcp_report(
        sensor,
        fit,
        dem,
        loo,
        f"written to {where}" if written else "dry run: site.json not changed",
    )
    return 0


def _run_convert(args: argparse.Namespace) -> int:
    from demtrack.core.camera.gcp_convert import convert_gcps, write_gcp_csv
    from demtrack.core.errors import CalibrationError

    if args.output.resolve() == args.input.resolve():
        raise CalibrationError("-o must not be the input file")
    gf = convert_gcps(
        args.input, args.format, crs=args.crs, to_crs=args.to_crs, vertical=args.vertical
    )
    write_gcp_csv(args.output, gf)
    shift = " (1-based pixels made 0-based: u, v minus 1)" if args.format == "imgraft" else ""
    print(f"{args.output}: {len(gf.names)} GCPs, CRS {gf.crs}{shift}")
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``calibrate`` (GCP) and ``calibrate-yaw`` commands."""
    p = sub.add_parser("calibrate", help="fit a camera to ground control points")
    add_site_argument(p)
    p.add_argument("--sensor", required=True, metavar="ID")
    p.add_argument("--gcps", required=True, metavar="FILE", help="GCP file (see docs)")
    p.add_argument(
        "--gcp-format", choices=GCP_FORMATS, default="csv",
        help="csv: name,u,v,x,y,z, 0-based pixels (default); imgraft: x y z u v, 1-based",
    )  # fmt: skip
    p.add_argument("--gcp-crs", metavar="CRS", help="CRS of x,y,z ('local' = site frame)")
    p.add_argument("--gcp-vertical", choices=("ellipsoidal", "orthometric"), help="heights' datum")
    p.add_argument(
        "--free",
        default=",".join(DEFAULT_FREE),
        metavar="LIST",
        help=f"parameters to fit, from {','.join(FREE_PARAMETERS)} (default yaw,tilt,roll; "
        "f ties fx and fy)",
    )
    p.add_argument(
        "--bound", action="append", metavar="NAME=LO,HI",
        help="bounds of a free parameter in its unit (repeatable)",
    )  # fmt: skip
    p.add_argument(
        "--prior", action="append", metavar="NAME=VALUE,SIGMA",
        help="prior on a free parameter, an extra residual (repeatable)",
    )  # fmt: skip
    p.add_argument(
        "--prior-position", metavar="X,Y,Z,SIGMA",
        help="surveyed optical centre and its 1-sigma (m): priors on x,y,z",
    )  # fmt: skip
    p.add_argument("--prior-crs", metavar="CRS", help="CRS of --prior-position (default local)")
    p.add_argument(
        "--prior-vertical", choices=("ellipsoidal", "orthometric"), help="its height's datum"
    )
    p.add_argument(
        "--pixel-sigma", type=positive, default=1.0, metavar="PX",
        help="pixel noise the priors are weighed against (default 1 px)",
    )  # fmt: skip
    p.add_argument(
        "--loss", default="soft_l1", choices=GCP_LOSSES, help="robust loss (default soft_l1)"
    )
    p.add_argument("--f-scale", type=positive, default=1.0, metavar="PX", help="loss scale")
    p.add_argument(
        "--outlier-px", type=positive, metavar="PX", help="outlier threshold (default auto)"
    )
    p.add_argument("--keep-outliers", action="store_true", help="flag but do not exclude")
    p.add_argument(
        "--height-tol", type=positive, default=0.5, metavar="M",
        help="GCP height vs DEM tolerance (default 0.5 m, at least 3 DEM sigma)",
    )  # fmt: skip
    p.add_argument(
        "--exclude-dem-flagged", action="store_true",
        help="also leave GCPs inconsistent with the DEM out of the fit",
    )  # fmt: skip
    p.add_argument(
        "--grazing-deg", type=non_negative, default=5.0, metavar="DEG", help="grazing-ray threshold"
    )
    p.add_argument("--dry-run", action="store_true", help="report only; leave site.json")
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=_run_gcps)

    p = sub.add_parser("convert-gcps", help="ImGRAFT or CSV GCPs to demtrack's GCP CSV")
    p.add_argument("input", type=Path, metavar="FILE")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="OUT.csv")
    p.add_argument("--format", choices=GCP_FORMATS, required=True, help="input format")
    p.add_argument("--crs", metavar="CRS", help="CRS of the input's x,y,z (ImGRAFT: required)")
    p.add_argument("--to-crs", metavar="CRS", help="re-project x,y,z to this CRS")
    p.add_argument("--vertical", choices=("ellipsoidal", "orthometric"), help="heights' datum")
    p.set_defaults(func=_run_convert)

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
