"""The weitsicht ``tennis_court_dem01`` case as demtrack objects (test helper, not a test).

Real material (``/work/shared/data/weitsicht``, Apache-2.0, read in place, never copied):
a bundle-adjusted camera (11648 x 8736 px, OpenCV distortion, ``k4 = 0``) about 960 m above
Queensland terrain, and the peer's own ground points of 42 of its pixels on the real DEM
``dem_01_gda94_mga55_ahd.tif`` (GDA94 / MGA zone 55, AHD heights, 5 m cells). The pose
used is the peer's, converted to the DEM's CRS (``peer_reference.pose_conversion``).

The site frame is anchored at the principal point's ground point; the DEM is imported with
the library's own path (``core.terrain.dem_import.import_dem``) onto a 5 m grid over the
footprint. Heights are AHD taken as ``h = H + N`` with ``N = 0`` for the DEM, the camera and
the GCPs alike: consistent, which is all a comparison within one frame needs.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
from pyproj import Transformer
from weitsicht_data import WEITSICHT_DIR

from demtrack.core.camera.gcp_io import Gcp, GcpFile, gcps_to_local
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.dem_import import grid_over, import_dem

DATA = WEITSICHT_DIR
CRS = "EPSG:28355"


@dataclass(frozen=True, eq=False)
class TennisCase:
    """The case in a site frame: truth camera, DEM and the peer's GCPs."""

    frame: LocalFrame
    dem: Dem
    camera: Camera
    gcps: tuple[Gcp, ...]
    gsd_m: float


def available() -> bool:
    """Whether the shared data is on this machine."""
    return (DATA / "cases.json").is_file() and (DATA / "dem_01_gda94_mga55_ahd.tif").is_file()


def _case() -> dict:
    doc = json.loads((DATA / "cases.json").read_text(encoding="utf-8"))
    return next(c for c in doc["cases"] if c["id"] == "tennis_court_dem01")


def load_tennis(cell_m: float = 5.0) -> TennisCase:
    """Build the case (a few seconds: the DEM import)."""
    case = _case()
    ref = case["peer_reference"]
    cam = case["camera"]
    w, h = case["image_size_px"]
    intr = Intrinsics(
        cam["fx"], cam["fy"], cam["cx"], cam["cy"], w, h,
        cam["k1"], cam["k2"], cam["p1"], cam["p2"], cam["k3"],
    )  # fmt: skip
    points = [*ref["grid"], *ref["example_points_01_02_tennis_court"]]
    corners = ref["footprint_corners_01_01"]["corners"]
    points += [dict(c, id=f"corner{k}") for k, c in enumerate(corners)]
    uv = np.array([p["pixel_center_origin"] for p in points], float)
    xyz = np.array([p["xyz"] for p in points], float)
    names = tuple(p.get("id", f"p{k}") for k, p in enumerate(points))
    to_ll = Transformer.from_crs(CRS, "EPSG:4326", always_xy=True)
    centre = xyz[names.index("g12")] if "g12" in names else xyz.mean(axis=0)
    lon0, lat0 = to_ll.transform(centre[0], centre[1])
    frame = LocalFrame(float(lat0), float(lon0), float(centre[2]))
    gf = GcpFile(names, uv, xyz, CRS, "orthometric")
    gcps = gcps_to_local(gf, frame, geoid_undulation_m=0.0)
    p = np.array([g.p_enu for g in gcps])
    pad = 150.0
    bounds = (p[:, 0].min() - pad, p[:, 1].min() - pad, p[:, 0].max() + pad, p[:, 1].max() + pad)
    dem = import_dem([DATA / "dem_01_gda94_mga55_ahd.tif"], frame, grid_over(bounds, cell_m)).dem
    pose = ref["pose_conversion"]
    c_grid = np.array(pose["position_in_dem_crs"], float)
    r_grid = np.array(pose["R_world_cam_opencv_axes_in_dem_crs"], float)
    # Camera axes from grid (E, N, up of MGA 55) into the site frame, through the CRS.
    e0 = np.array(frame.to_enu_from_crs(*c_grid, CRS, geoid_undulation_m=0.0), float)
    axes = []
    for j in range(3):
        tip = c_grid + 10.0 * r_grid[:, j]
        axes.append(np.array(frame.to_enu_from_crs(*tip, CRS, geoid_undulation_m=0.0)) - e0)
    m = np.column_stack(axes)
    uu, _, vt = np.linalg.svd(m)
    r_site = uu @ vt
    gsd = float(np.median([q["gsd_m"] for q in points if "gsd_m" in q]))
    return TennisCase(frame, dem, Camera(intr, e0, r_site), tuple(gcps), gsd)


def rotation_error_deg(a: Camera, b: Camera) -> float:
    """Angle of the rotation between two cameras' orientations (deg)."""
    r = a.R_world_cam.T @ b.R_world_cam
    return float(np.degrees(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0))))
