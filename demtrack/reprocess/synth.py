"""The synthetic reprocessing archive: a 12-camera sample site and a million detections.

:func:`make_camera_site` copies the sample site and replaces its three cameras by
clusters of three fixed cameras, each cluster on a 25 m mast set back 40 m inside the
road loop from one spot of the loop (its east, north, west and south apexes in turn),
the three of a cluster looking at their spot from directions 60 degrees apart with a
40 degree lens. A cluster's cameras see the same stretch of road; clusters see
disjoint ones, so the 12 cameras make four sensor groups (:mod:`.groups`).

:func:`synth_archive` renders the sample scenarios on that site with the real camera
model - the targets' box points cast against the DEM, crowns and roofs hiding them,
box noise, misses, false alarms (:mod:`demtrack.samplesite.scene_render`) - once per
(scenario, seed) variant, then stamps copies of the variants at successive times, a
quiet gap between copies, until the archive holds the detections asked for.
"""

from __future__ import annotations

import json
import math
import os
import shutil
from pathlib import Path

import numpy as np
import pyarrow as pa

from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pointing import point_head_at
from demtrack.core.errors import InputFileError

from .archive import ARCHIVE_SCHEMA, table_from_detections, write_archive

__all__ = ["SPOTS", "camera_specs", "make_camera_site", "synth_archive"]

#: Parameter along the loop (0 = east apex, counter-clockwise) of each cluster's spot.
SPOTS = (0.0, 0.25, 0.5, 0.75)
MAST_M = 25.0
SETBACK_M = 40.0
HFOV_DEG = 40.0
SPREAD_DEG = 60.0


def camera_specs(world: object, n_cameras: int) -> list[tuple[str, np.ndarray, np.ndarray]]:
    """``(id, position_enu, look_at_enu)`` of ``n_cameras`` (clusters of three, module notes)."""
    loop = world.roads["loop"]  # type: ignore[attr-defined]
    centre = loop[:-1].mean(axis=0)
    out = []
    for k in range(n_cameras):
        spot_param = SPOTS[(k // 3) % len(SPOTS)] + 0.125 * (k // (3 * len(SPOTS)))
        sx, sy = loop[int(round(spot_param * (len(loop) - 1))) % (len(loop) - 1)]
        inward = math.atan2(centre[1] - sy, centre[0] - sx)
        a = inward + math.radians(SPREAD_DEG) * ((k % 3) - 1)
        x, y = sx + SETBACK_M * math.cos(a), sy + SETBACK_M * math.sin(a)
        z = float(world.surface_z(np.array(x), np.array(y))) + MAST_M  # type: ignore[attr-defined]
        gz = float(world.ground_z(sx, sy))  # type: ignore[attr-defined]
        out.append((f"c{k + 1:02d}", np.array([x, y, z]), np.array([sx, sy, gz])))
    return out


def make_camera_site(
    sample_site: str | os.PathLike[str], out: str | os.PathLike[str], n_cameras: int = 12
) -> Path:
    """Copy the sample site to ``out`` with ``n_cameras`` fixed cameras (module notes)."""
    from demtrack.core.camera.pinhole import Intrinsics
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.scene_render import site_world

    if n_cameras < 1:
        raise InputFileError(f"--cameras must be at least 1, got {n_cameras}")
    src, dst = Path(sample_site), Path(out)
    site = load_site(src)
    world = site_world(site)
    if dst.exists():
        raise InputFileError(f"site folder {dst} exists: choose a new one")
    shutil.copytree(src, dst, ignore=shutil.ignore_patterns("images", "videos", "*.sqlite3*"))
    doc = json.loads((dst / "site.json").read_text("utf-8"))
    f = (1280 / 2) / math.tan(math.radians(HFOV_DEG / 2))
    intr = Intrinsics(f, f, 639.5, 359.5, 1280, 720, k1=-0.04)
    sensors = []
    for sid, pos, look in camera_specs(world, n_cameras):
        head = PanTiltHead(pos, 0.0, intr)
        pan, tilt = point_head_at(head, look)
        sensors.append(
            {
                "id": sid,
                "name": f"mast {sid}",
                "head": head.to_dict(),
                "pan_deg": pan,
                "tilt_deg": tilt,
            }
        )
    doc["sensors"] = sensors
    doc["name"] = f"{doc.get('name', 'sample site')} ({n_cameras} cameras)"
    (dst / "site.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")
    # truth.json's true yaws are the sample cameras' (cam1..cam3): none of these ids.
    return dst


def _variant(site: object, name: str, seed: int) -> pa.Table:
    from demtrack.samplesite.scenarios import ScenarioParams, make_scenario

    sc = make_scenario(site, name, ScenarioParams(seed=seed))  # type: ignore[arg-type]
    return table_from_detections(sc.detections)


def synth_archive(
    site_dir: str | os.PathLike[str],
    out: str | os.PathLike[str],
    n_detections: int,
    *,
    start_s: float = 1_796_133_600.0,
    gap_s: float = 90.0,
    scenarios: tuple[str, ...] = ("vehicle-run", "passing-vehicles"),
    seeds: int = 2,
    progress: object = None,
) -> dict[str, float]:
    """Write an archive of at least ``n_detections`` rendered on ``site_dir`` (module notes).

    Returns counts: ``detections``, ``copies``, ``variants``, ``t_first``, ``t_last``.
    """
    from demtrack.core.site.folder import load_site

    if n_detections < 1:
        raise InputFileError(f"--detections must be at least 1, got {n_detections}")
    site = load_site(site_dir)
    variants = [_variant(site, name, s) for s in range(seeds) for name in scenarios]
    variants = [v for v in variants if v.num_rows]
    if not variants:
        raise InputFileError(f"no camera of {site_dir} sees the scenarios' targets")
    pieces, total, t0, k = [], 0, float(start_s), 0
    while total < n_detections:
        v = variants[k % len(variants)]
        t = v["t_s"].to_numpy()
        shifted = v.set_column(v.schema.get_field_index("t_s"), "t_s", pa.array(t + (t0 - t.min())))
        pieces.append(shifted)
        total += v.num_rows
        t0 += float(t.max() - t.min()) + gap_s
        k += 1
    table = pa.concat_tables(pieces).cast(ARCHIVE_SCHEMA)
    table = table.set_column(0, "seq", pa.array(np.arange(table.num_rows, dtype=np.int64)))
    write_archive(table, out)
    t_all = table["t_s"].to_numpy()
    return {
        "detections": table.num_rows,
        "copies": k,
        "variants": len(variants),
        "t_first": float(t_all.min()),
        "t_last": float(t_all.max()),
    }
