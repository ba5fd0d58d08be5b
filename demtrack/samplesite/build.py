"""Write the sample site folder: laser-built DEM, orthophoto, roads, cameras, images.

The steps follow Collins et al. (1998): grid a helicopter laser scan at 0.5 m with
per-cell mean, variance and count; fill the holes from a 30 m coarse DEM; calibrate each
pan-tilt head's yaw from landmark pan readings; then render each camera's view of the
site by ray casting the DEM and draping the orthophoto. Each sensor is written with its
head's ``slew_limits`` and its telemetry's ``pose_latency_s`` (it is a PTZ head, at rest:
``active`` stays false).
Deterministic for a given seed.

The site is anchored at the real Bushy Run with its real vertical datum: ``site.json``
states EGM96 (PROJ's ``egm96_15.gtx``, Debian's proj-data; N = -33.97 m at the anchor),
so the console's elevation and the KML/GPX exports are sea-level heights, 34 m above the
ellipsoidal ones. Building needs the grid: without it the build stops with one line.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from PIL import Image

from demtrack.core.camera.pantilt import wrap_deg
from demtrack.core.errors import SiteError
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.geo.geoid import GeoidModel
from demtrack.core.geolocation.roads import RoadNetwork
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.raycast.light import light_kernels
from demtrack.core.site.folder import MANIFEST, Sensor, site_manifest
from demtrack.core.site.orthophoto import write_orthophoto
from demtrack.core.site.render import render_view
from demtrack.core.site.road_io import write_roads_geojson
from demtrack.core.terrain.crs_import import local_crs_wkt
from demtrack.core.terrain.dem import Dem

from .cameras import TELEMETRY_LATENCY_S, sighting_heads, slew_limits_of
from .kernel_warmup import load_numba_target
from .masks import MASK_RANGE_M, crown_mask, write_mask
from .ortho import ortho_grid, paint_orthophoto
from .scan import coarse_dem, simulate_laser_scan
from .world import ANCHOR, EXTENT_M, make_world

if TYPE_CHECKING:
    from .kernel_warmup import KernelWarmers

__all__ = ["DEM_CELL_M", "build_sample_site"]

DEM_CELL_M = 0.5
SITE_NAME = "Bushy Run (synthetic sample site)"


def build_sample_site(
    out_dir: str | Path,
    *,
    seed: int = 7,
    log: Callable[[str], None] | None = None,
    warmers: KernelWarmers | None = None,
) -> Path:
    """Generate the sample site into ``out_dir`` (created; must be empty or a site).

    Returns the folder. ``log`` receives one line per step with its duration.
    ``warmers`` (:class:`~demtrack.samplesite.kernel_warmup.KernelWarmers`, optional) are
    child processes compiling the ray-casting kernels into numba's cache while the scan,
    DEM and orthophoto are made; the camera views are rendered once they are done (they
    are stopped if the build fails first), with the light kernels
    (:func:`~demtrack.core.raycast.light.use_light_kernels`).
    """
    out = Path(out_dir)
    if out.exists() and any(out.iterdir()) and not (out / MANIFEST).exists():
        if warmers is not None:
            warmers.stop()
        raise SiteError(f"refusing to write the sample site into a non-empty folder: {out}")
    try:
        _build(out, seed, log, warmers)
    except BaseException:
        if warmers is not None:
            warmers.stop()
        raise
    return out


def _build(
    out: Path, seed: int, log: Callable[[str], None] | None, warmers: KernelWarmers | None
) -> None:
    """The build's steps (see :func:`build_sample_site`)."""
    # The real Bushy Run's vertical datum: heights people read (the console's elevation,
    # KML, GPX) are above EGM96, about 34 m above the ellipsoidal heights there. Looked up
    # first, so a missing grid stops the build before anything is written.
    geoid = GeoidModel.egm96()
    (out / "images").mkdir(parents=True, exist_ok=True)
    say = log or (lambda _msg: None)
    t0 = time.perf_counter()

    def step(msg: str) -> None:
        say(f"[{time.perf_counter() - t0:5.1f} s] {msg}")

    world = make_world(seed)
    frame = LocalFrame(*ANCHOR)
    crs = local_crs_wkt(frame)

    points = simulate_laser_scan(world)
    np.save(out / "laser_points.npy", points.astype(np.float32))
    coarse = replace(coarse_dem(world), crs_wkt=crs)
    coarse.write(out / "coarse_dem_30m.tif")
    box = (-EXTENT_M, -EXTENT_M, EXTENT_M, EXTENT_M)
    raw = Dem.from_points(points, DEM_CELL_M, bounds=box, crs_wkt=crs)
    dem = raw.fill_holes(coarse)
    dem.write(out / "dem.tif")
    step(
        f"DEM {dem.grid.ncols}x{dem.grid.nrows} at {DEM_CELL_M} m from {len(points):,} laser"
        f" points; {100 * raw.coverage:.1f} % of cells hit, {100 * dem.filled.mean():.1f} %"
        " filled from the 30 m DEM"
    )

    grid = ortho_grid()
    rgb = paint_orthophoto(world, grid)
    write_orthophoto(out / "ortho.tif", rgb, grid, crs)
    roads = RoadNetwork.from_coordinates(
        list(world.roads.values()), list(world.roads), [world.road_width_m] * len(world.roads)
    )
    write_roads_geojson(out / "roads.geojson", roads, frame)
    step(f"orthophoto {grid.ncols}x{grid.nrows} at {grid.cell_m} m; {len(roads)} roads")
    if warmers is not None:
        # Numba's first load of a kernel in a process sets up its CPU target (about 1 s
        # of imports): done here, it overlaps the compile the build waits for.
        load_numba_target()
        warmers.wait()  # a failed job only means the render compiles what is missing
        step("ray-casting kernels compiled (beside the steps above)")

    def view(item: tuple) -> tuple:
        spec, head, pan, tilt = item
        cal = head.calibrate()
        calibrated = head.with_mount_yaw(cal.yaw_deg)
        image_path = out / "images" / f"{spec.id}.png"
        sensor = Sensor(
            spec.id,
            spec.name,
            calibrated,
            pan,
            tilt,
            image_path,
            pose_latency_s=TELEMETRY_LATENCY_S,
            slew_limits=slew_limits_of(spec),
        )
        Image.fromarray(render_view(sensor.camera, dem, rgb, grid)).save(image_path)
        # the video's camera (true mount yaw): its near swaying crowns, ignored by watch
        mask = crown_mask(head.camera_at(pan, tilt), dem, world)
        write_mask(out / "masks" / f"{spec.id}.png", mask)
        return spec, head, cal, sensor, float(mask.mean())

    sensors, truth = [], {}
    # Two cameras at a time: the light kernels release the GIL. Same pixels as the fast
    # kernels, which take three times as long to compile (a cold start's render).
    with light_kernels(), ThreadPoolExecutor(2) as pool:
        RayCaster.for_dem(dem)  # the pyramid (in numpy), once, before the threads share it
        for spec, head, cal, sensor, masked in pool.map(view, sighting_heads(world)):
            sensors.append(sensor)
            truth[spec.id] = {
                "true_mount_yaw_deg": spec.true_mount_yaw_deg,
                "calibrated_mount_yaw_deg": cal.yaw_deg,
                "yaw_error_deg": float(wrap_deg(cal.yaw_deg - spec.true_mount_yaw_deg)),
                "outliers": [head.landmarks[i].name for i in np.flatnonzero(cal.outliers)],
            }
            step(
                f"{spec.id} ({spec.name}): yaw {cal.yaw_deg:.3f} deg (true"
                f" {spec.true_mount_yaw_deg}), rms {cal.rms_deg:.3f} deg, image rendered;"
                f" mask: {100 * masked:.1f} % (crowns nearer than {MASK_RANGE_M:.0f} m)"
            )
    doc = site_manifest(
        SITE_NAME, frame, sensors, out, geoid=geoid, extra={"generator": {"seed": seed}}
    )
    step(
        f"vertical datum EGM96: N = {doc['geoid_undulation_m']:.2f} m at the anchor, so"
        f" sea-level heights are {-doc['geoid_undulation_m']:.2f} m above ellipsoidal ones"
    )
    (out / MANIFEST).write_text(json.dumps(doc, indent=2), "utf-8")
    (out / "truth.json").write_text(json.dumps({"sensors": truth}, indent=2), "utf-8")
    step(f"site written to {out}")
