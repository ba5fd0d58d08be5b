"""The sample site's three pan-tilt cameras and their landmark sightings.

The cameras are pan-tilt-zoom heads (:func:`slew_limits_of`, written to ``site.json`` as
each sensor's ``slew_limits``), left at rest (``active`` false) for every scenario but
the active ones, whose heads move and report their pose (:mod:`.active_scenario`) with
stamps :data:`TELEMETRY_LATENCY_S` late, the sensors' ``pose_latency_s``.

Each camera has a true mount yaw (unknown to the operator) and a commanded pan and tilt
that point it at part of the site. The operator's yaw comes from landmark sightings:
surveyed points (building corners, road junctions, lot corners) centred in the image with
the pan angle read off the head, with 0.03 degrees of reading noise; one sighting on the
visitor-centre camera is a deliberate 2-degree blunder that calibration must reject.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from demtrack.core.camera.pantilt import LandmarkReading, PanTiltHead, wrap_deg
from demtrack.core.camera.pinhole import Intrinsics

from .world import PARKING, World

__all__ = [
    "CameraSpec",
    "SAMPLE_CAMERAS",
    "TELEMETRY_LATENCY_S",
    "landmark_points",
    "sighting_heads",
    "slew_limits_of",
]

PAN_NOISE_DEG = 0.03
#: How late the simulated heads' telemetry stamps are relative to the frames (s).
TELEMETRY_LATENCY_S = 0.08
BLUNDER_DEG = 2.0


@dataclass(frozen=True)
class CameraSpec:
    """Where a sample camera stands and what it looks at (site frame, m)."""

    id: str
    name: str
    x: float
    y: float
    height_above_surface_m: float
    look_at_xy: tuple[float, float]
    true_mount_yaw_deg: float
    hfov_deg: float
    width: int = 1280
    height: int = 720
    k1: float = -0.04


# Pointing: cam1 (wide) sees the loop's west and south sides and the top of the spur, cam2
# (wide) the spur and the parking lot, cam3 (on a 30 m mast, high enough to look down on
# the north side over the crowns) the north, west and south sides; the east side is left
# unseen, so a vehicle coming up the spur and turning north crosses a hand-off gap of a
# few seconds (as in the VSAM experiment).
SAMPLE_CAMERAS = (
    CameraSpec("cam1", "Museum roof", -33.0, 105.0, 8.0, (-40.0, -40.0), 14.7, 80.0),
    CameraSpec("cam2", "Visitor centre roof", 73.0, -61.0, 5.0, (88.0, -90.0), -148.7, 90.0),
    CameraSpec("cam3", "East mast", 142.0, 58.0, 30.0, (40.0, 17.0), -62.1, 76.0),
)


def slew_limits_of(spec: CameraSpec) -> dict[str, float]:
    """The head's slew limits (``SlewLimits`` field names): a surveillance PTZ head.

    60 and 40 deg/s pan and tilt, 120 deg/s^2, the zoom 10 deg/s of field of view from
    the lens's own (widest) down to 4 degrees; tilt from 60 degrees down to 20 up. The
    mast camera's heavier housing turns slower (45 deg/s, 90 deg/s^2).
    """
    mast = spec.height_above_surface_m >= 20.0
    return {
        "pan_rate_deg_s": 45.0 if mast else 60.0,
        "tilt_rate_deg_s": 40.0,
        "accel_deg_s2": 90.0 if mast else 120.0,
        "zoom_rate_deg_s": 10.0,
        "tilt_min_deg": -60.0,
        "tilt_max_deg": 20.0,
        "hfov_min_deg": 4.0,
        "hfov_max_deg": spec.hfov_deg,
    }


def landmark_points(world: World) -> dict[str, tuple[float, float, float]]:
    """Surveyed landmarks: name -> (e, n, u) in the site frame (m)."""
    pts: dict[str, tuple[float, float]] = {}
    for b in world.buildings:
        pts[f"{b.name} SW corner"] = (b.x0, b.y0)
        pts[f"{b.name} NE corner"] = (b.x1, b.y1)
    loop, entrance, spur = world.roads["loop"], world.roads["entrance"], world.roads["parking spur"]
    pts["entrance junction"] = tuple(entrance[-1])
    pts["spur junction"] = tuple(spur[0])
    px0, px1, py0, py1 = PARKING
    pts["lot SW corner"] = (px0, py0)
    pts["lot NE corner"] = (px1, py1)
    pts["loop north apex"] = tuple(loop[np.argmax(loop[:, 1])])
    pts["loop east apex"] = tuple(loop[np.argmax(loop[:, 0])])
    out = {}
    for name, (e, n) in pts.items():
        z = float(np.fmax(world.ground_z(e, n), world.building_z(e, n)))
        out[name] = (float(e), float(n), z)
    return out


def camera_position(spec: CameraSpec, world: World) -> np.ndarray:
    """Optical centre (m): the spec's height above the first-return surface."""
    z = float(world.surface_z(np.array(spec.x), np.array(spec.y)))
    return np.array([spec.x, spec.y, z + spec.height_above_surface_m])


def pointing(spec: CameraSpec, world: World) -> tuple[float, float]:
    """True azimuth and tilt (degrees) from the camera to its look-at ground point."""
    pos = camera_position(spec, world)
    tx, ty = spec.look_at_xy
    tz = float(world.ground_z(tx, ty))
    dx, dy, dz = tx - pos[0], ty - pos[1], tz - pos[2]
    return float(np.degrees(np.arctan2(dx, dy))), float(
        np.degrees(np.arctan2(dz, np.hypot(dx, dy)))
    )


def intrinsics_of(spec: CameraSpec) -> Intrinsics:
    """Pinhole intrinsics with the spec's horizontal field of view and mild barrel."""
    f = (spec.width / 2) / np.tan(np.radians(spec.hfov_deg / 2))
    return Intrinsics(
        f, f, (spec.width - 1) / 2, (spec.height - 1) / 2, spec.width, spec.height, k1=spec.k1
    )


def sighting_heads(
    world: World, seed: int = 17
) -> list[tuple[CameraSpec, PanTiltHead, float, float]]:
    """For each camera: its spec, the head with noisy landmark pans, and the pan/tilt.

    The head's ``mount_yaw_deg`` is still the true one here; the site writer replaces it
    with the calibrated estimate, as an operator would.
    """
    rng = np.random.default_rng(seed)
    marks = landmark_points(world)
    out = []
    for spec in SAMPLE_CAMERAS:
        pos = camera_position(spec, world)
        readings = []
        for name, (e, n, u) in marks.items():
            az = float(np.degrees(np.arctan2(e - pos[0], n - pos[1])))
            pan = az - spec.true_mount_yaw_deg + rng.normal(0.0, PAN_NOISE_DEG)
            if spec.id == "cam2" and name == "lot NE corner":
                pan += BLUNDER_DEG
            readings.append(LandmarkReading(name, e, n, float(wrap_deg(pan)), u))
        head = PanTiltHead(pos, spec.true_mount_yaw_deg, intrinsics_of(spec), tuple(readings))
        az, tilt = pointing(spec, world)
        out.append((spec, head, float(wrap_deg(az - spec.true_mount_yaw_deg)), tilt))
    return out
