"""Tracking scenarios on the sample site, with ground truth.

True 3-D target paths (:mod:`.routes` on the analytic world's roads and ground) are
projected into each camera with the real camera model: the site's pan-tilt head with the
**true** mount yaw from ``truth.json`` (the site stores the calibrated one, so the
calibration error is part of the experiment). A target is a box (vehicle 4.5 x 1.8 x
1.5 m along its heading, human 0.5 x 0.5 x 1.8 m); its image box is the bounding box of
the projections of the sample points on its surface that the camera sees: a ray from the
camera to each point is cast against the site DEM (a first-return surface, so tree crowns
and roofs occlude), and points behind the surface are dropped. Where a crown hides the
lower part of a vehicle, the box bottom rises onto the crown - the VSAM paper's failure
mode. Boxes then get pixel noise on each edge; detections are missed at random and false
alarms appear at random. Everything is deterministic for a seed.

Scenarios (:data:`SCENARIOS`):

``vehicle-run``
    The paper's run: a car drives in from the west entrance, round the loop's south side
    to the south-east, down the spur into the parking lot, stops, turns around, drives
    back up and continues counter-clockwise round the loop (east side unseen, then the
    north and west sides). Seen by all three cameras in turn, with hand-off gaps.
``pedestrians``
    Three people crossing the field, two of them crossing each other's path.
``passing-vehicles``
    Two cars in opposite lanes passing each other at the loop's south-west corner.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from demtrack.core.camera.pinhole import Camera
from demtrack.core.errors import InputFileError, SiteError
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import Detection, TruthPath

from .routes import Motion, Route, drive, offset_lane, resample_polyline, smooth_polyline
from .world import World, make_world

__all__ = [
    "SCENARIOS",
    "SIZES_M",
    "Scenario",
    "ScenarioParams",
    "Target",
    "image_boxes",
    "site_world",
    "make_scenario",
    "render_targets",
    "read_truth_json",
    "target_points",
    "true_cameras",
    "write_truth_json",
]

#: Nominal box of each class: (length along heading, width, height) in metres.
SIZES_M: dict[str, tuple[float, float, float]] = {
    "vehicle": (4.5, 1.8, 1.5),
    "human": (0.5, 0.5, 1.8),
}
LANE_OFFSET_M = 1.5  # right-hand traffic: a car drives this far right of the centreline


@dataclass(frozen=True)
class ScenarioParams:
    """How detections are made from the true scene.

    Parameters
    ----------
    noise_px : float
        1-sigma noise of each box edge (px).
    p_miss : float
        Probability that a visible target is not detected in a frame.
    false_alarm_rate : float
        Mean false alarms per camera frame (Poisson).
    seed : int
        Seed of every random draw.
    rate_hz : float
        Frame rate of the (genlocked) cameras.
    min_visible : float
        A target is detected only when at least this fraction of its sample points is
        seen (the rest hidden by terrain, crowns, roofs or the image border).
    """

    noise_px: float = 1.0
    p_miss: float = 0.05
    false_alarm_rate: float = 0.02
    seed: int = 0
    rate_hz: float = 10.0
    min_visible: float = 0.3

    def __post_init__(self) -> None:
        checks = (
            ("noise_px", self.noise_px >= 0),
            ("p_miss", 0 <= self.p_miss < 1),
            ("false_alarm_rate", self.false_alarm_rate >= 0),
            ("rate_hz", self.rate_hz > 0),
            ("min_visible", 0 < self.min_visible <= 1),
        )
        for name, ok in checks:
            value = getattr(self, name)
            if not (math.isfinite(value) and ok):
                raise SiteError(f"scenario parameter {name} is out of range: {value}")


@dataclass(frozen=True, eq=False)
class Target:
    """One moving object: its class, box size and motion."""

    target_id: int
    cls: str
    motion: Motion
    size_m: tuple[float, float, float]


@dataclass(frozen=True, eq=False)
class Scenario:
    """Detections with their ground truth.

    Parameters
    ----------
    name : str
        Scenario name.
    params : ScenarioParams
        How it was made.
    detections : list of Detection
        In time order, then sensor.
    truths : list of TruthPath
        True centre of each target's footprint on the ground (z = true ground).
    stats : dict
        Counts: frames, visible, occluded, detected, partly hidden, missed, false alarms.
    """

    name: str
    params: ScenarioParams
    detections: list[Detection]
    truths: list[TruthPath]
    stats: dict[str, int] = field(default_factory=dict)


def true_cameras(site: Site) -> dict[str, Camera]:
    """Each sensor's camera with the true mount yaw from ``truth.json`` (if present)."""
    truth_path = site.root / "truth.json"
    yaws: dict[str, float] = {}
    if truth_path.is_file():
        doc = json.loads(truth_path.read_text("utf-8"))
        yaws = {k: float(v["true_mount_yaw_deg"]) for k, v in doc.get("sensors", {}).items()}
    out = {}
    for sid, sensor in site.sensors.items():
        head = sensor.head.with_mount_yaw(yaws[sid]) if sid in yaws else sensor.head
        out[sid] = head.camera_at(sensor.pan_deg, sensor.tilt_deg)
    return out


def target_points(
    xy: np.ndarray, heading: np.ndarray, size_m: tuple[float, float, float], world: World
) -> np.ndarray:
    """Sample points on the surface of a target's box (site frame, m).

    Parameters
    ----------
    xy, heading : ndarray, shape (2,) or (f, 2)
        Footprint centre (m) and unit heading, for one pose or ``f`` poses.
    size_m : tuple of 3 float
        Length along the heading, width, height (m).
    world : World
        Each point stands on the true ground below it.

    Returns
    -------
    ndarray, shape (k, 3) or (f, k, 3)
        A grid over the box's faces.
    """
    single = np.ndim(xy) == 1
    xy = np.atleast_2d(np.asarray(xy, dtype=np.float64))
    h = np.atleast_2d(np.asarray(heading, dtype=np.float64))
    length, width, height = size_m
    nl, nw, nh = (7, 4, 5) if length > 1.0 else (3, 3, 7)
    a, b, c = np.meshgrid(
        np.linspace(-0.5, 0.5, nl), np.linspace(-0.5, 0.5, nw), np.linspace(0, 1, nh), indexing="ij"
    )
    surface = (np.abs(a) == 0.5) | (np.abs(b) == 0.5) | (c == 0) | (c == 1)
    a, b, c = a[surface], b[surface], c[surface]
    right = np.column_stack([h[:, 1], -h[:, 0]])
    pxy = (
        xy[:, None, :]
        + (a * length)[None, :, None] * h[:, None, :]
        + (b * width)[None, :, None] * right[:, None, :]
    )
    z = world.ground_z(pxy[..., 0], pxy[..., 1]) + (c * height)[None, :]
    out = np.concatenate([pxy, z[..., None]], axis=-1)
    return out[0] if single else out


def image_boxes(
    camera: Camera, caster: RayCaster, points: np.ndarray, border_px: float = 2.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image boxes of the visible parts of targets, and the fractions seen.

    Parameters
    ----------
    camera : Camera
        The true camera.
    caster : RayCaster
        The site DEM (first-return surface).
    points : ndarray, shape (f, k, 3)
        Sample points of ``f`` target poses (:func:`target_points`).
    border_px : float
        A box this close to the image border is cut by it, and is not reported.

    Returns
    -------
    boxes : ndarray, shape (f, 4)
        ``(u_min, v_min, u_max, v_max)`` (px); NaN where nothing is seen or the box is cut.
    fraction : ndarray, shape (f,)
        Fraction of the points seen (in front, on the image, not behind the surface).
    in_view : ndarray of bool, shape (f,)
        Some point projects onto the image (hidden or not).
    """
    f, k, _ = points.shape
    flat = points.reshape(-1, 3)
    u, v, in_front = camera.project(flat)
    intr = camera.intrinsics
    on_image = in_front & intr.in_image(np.nan_to_num(u, nan=-1e9), np.nan_to_num(v, nan=-1e9))
    seen = np.zeros(f * k, dtype=bool)
    idx = np.flatnonzero(on_image)
    if idx.size:
        origin = np.asarray(camera.position_enu, dtype=np.float64)
        vec = flat[idx] - origin
        dist = np.linalg.norm(vec, axis=1)
        # A surface crossing more than 1 m before the point hides it; the margin absorbs
        # the DEM's centimetres of error where a ray grazes the ground at a target's feet.
        # No angular index: for these scattered target points building one costs as much
        # CPU as it saves, and on a cold machine its kernels cost a minute to compile.
        hits = caster.cast(
            np.broadcast_to(origin, vec.shape).copy(),
            vec,
            np.maximum(dist - 1.0, 0.0),
            mode="first",
            coherent=False,
        )
        seen[idx] = hits.counts == 0
    seen = seen.reshape(f, k)
    uu = np.where(seen, u.reshape(f, k), np.nan)
    vv = np.where(seen, v.reshape(f, k), np.nan)
    any_seen = seen.any(axis=1)
    boxes = np.full((f, 4), np.nan)
    if any_seen.any():
        boxes[any_seen] = np.column_stack(
            [
                np.nanmin(uu[any_seen], axis=1),
                np.nanmin(vv[any_seen], axis=1),
                np.nanmax(uu[any_seen], axis=1),
                np.nanmax(vv[any_seen], axis=1),
            ]
        )
    w, h = intr.width, intr.height
    with np.errstate(invalid="ignore"):
        cut = (
            (boxes[:, 0] < border_px - 0.5)
            | (boxes[:, 1] < border_px - 0.5)
            | (boxes[:, 2] > w - 0.5 - border_px)
            | (boxes[:, 3] > h - 0.5 - border_px)
        )
    boxes[cut] = np.nan
    return boxes, seen.mean(axis=1), on_image.reshape(f, k).any(axis=1)


# ---------------------------------------------------------------- the routes
def _loop_span(loop: np.ndarray, i0: int, i1: int, step: int = 1) -> np.ndarray:
    """Loop vertices from index ``i0`` to ``i1`` going ``step`` (+1 counter-clockwise)."""
    n = len(loop) - 1  # the polyline is closed: the last vertex repeats the first
    out, i = [], i0 % n
    while True:
        out.append(loop[i])
        if i == i1 % n:
            break
        i = (i + step) % n
    return np.array(out)


def _nearest(poly: np.ndarray, xy: tuple[float, float]) -> int:
    return int(np.argmin(np.hypot(poly[:, 0] - xy[0], poly[:, 1] - xy[1])))


def _concat(*parts: np.ndarray) -> np.ndarray:
    return resample_polyline(np.vstack(parts), 0.5)


def _vehicle_run(world: World) -> list[Target]:
    loop, ent, spur = world.roads["loop"], world.roads["entrance"], world.roads["parking spur"]
    j_ent = _nearest(loop, tuple(ent[-1]))
    j_spur = _nearest(loop, tuple(spur[0]))
    end = spur[-1]
    heading = (spur[-1] - spur[-2]) / np.linalg.norm(spur[-1] - spur[-2])
    right = np.array([heading[1], -heading[0]])
    radius = 6.0
    centre = end + radius * right
    phi = np.linspace(0, np.pi, 25)[1:]
    # Turn round to the right in the lot: a half circle, clockwise, from the spur's end.
    rel = -radius * right
    cw = np.column_stack(
        [
            rel[0] * np.cos(phi) + rel[1] * np.sin(phi),
            -rel[0] * np.sin(phi) + rel[1] * np.cos(phi),
        ]
    )
    u_turn = centre + cw
    back_from = _nearest(spur, (100.0, -100.0))
    approach = _concat(ent, _loop_span(loop, j_ent, j_spur, +1), spur)
    leave = _concat(spur[back_from::-1], _loop_span(loop, j_spur, j_ent + 30, +1))
    centre_line = smooth_polyline(np.vstack([approach, u_turn, leave]), 8.0)
    xy = resample_polyline(offset_lane(centre_line, LANE_OFFSET_M), 0.5)
    s = Route(xy).s_m
    # The stop: where the lane passes the spur's end, on the way in.
    n_in = len(approach) + 10
    s_end = float(s[_nearest(xy[:n_in], tuple(end + LANE_OFFSET_M * right))])
    spur_len = float(np.sum(np.hypot(*np.diff(spur, axis=0).T)))
    lot0, lot1 = s_end - 40.0, s_end + np.pi * radius + 40.0
    motion = drive(
        Route(xy, stops=((s_end, 5.0),)),
        cruise_m_s=8.0,
        speed_limits=((s_end - spur_len, lot0, 6.0), (lot0, lot1, 4.0)),
    )
    return [Target(1, "vehicle", motion, SIZES_M["vehicle"])]


def _walk(a: tuple[float, float], b: tuple[float, float], wiggle_m: float) -> np.ndarray:
    pa, pb = np.array(a), np.array(b)
    t = np.linspace(0, 1, 200)
    d = pb - pa
    side = np.array([d[1], -d[0]]) / np.linalg.norm(d)
    xy = pa + t[:, None] * d + (wiggle_m * np.sin(2 * np.pi * 1.5 * t))[:, None] * side
    return resample_polyline(xy, 0.25)


def _pedestrians(world: World) -> list[Target]:
    walks = [
        ((-85.0, -45.0), (-25.0, 50.0), 1.4, 0.0, 2.0),
        ((-30.0, -50.0), (-85.0, 40.0), 1.3, 4.0, 1.5),
        ((-60.0, 60.0), (10.0, -15.0), 1.5, 8.0, 1.0),
    ]
    out = []
    for k, (a, b, speed, t0, wiggle) in enumerate(walks, start=1):
        motion = drive(
            Route(_walk(a, b, wiggle)),
            t0_s=t0,
            cruise_m_s=speed,
            lateral_acc_m_s2=1.0,
            acc_m_s2=0.5,
        )
        out.append(Target(k, "human", motion, SIZES_M["human"]))
    return out


def _passing_vehicles(world: World) -> list[Target]:
    loop, ent = world.roads["loop"], world.roads["entrance"]
    j_ent = _nearest(loop, tuple(ent[-1]))
    j_south = _nearest(loop, (0.0, -70.0))
    j_north = _nearest(loop, (-60.0, 95.0))
    a_line = smooth_polyline(np.vstack([ent, _loop_span(loop, j_ent, j_south, +1)]), 8.0)
    b_line = smooth_polyline(_loop_span(loop, j_south, j_north, -1), 8.0)
    a_path = resample_polyline(offset_lane(a_line, LANE_OFFSET_M), 0.5)
    b_path = resample_polyline(offset_lane(b_line, LANE_OFFSET_M), 0.5)
    a = drive(Route(a_path), cruise_m_s=8.0)
    b = drive(Route(b_path), t0_s=2.0, cruise_m_s=7.0)
    return [
        Target(1, "vehicle", a, SIZES_M["vehicle"]),
        Target(2, "vehicle", b, SIZES_M["vehicle"]),
    ]


#: Scenario name -> targets on a world.
SCENARIOS: dict[str, Callable[[World], list[Target]]] = {
    "vehicle-run": _vehicle_run,
    "pedestrians": _pedestrians,
    "passing-vehicles": _passing_vehicles,
}


# ---------------------------------------------------------------- rendering
def _truth(target: Target, world: World, dt_s: float = 0.05) -> TruthPath:
    m = target.motion
    t = np.arange(m.t_start, m.t_end + 1e-9, dt_s)
    xy, _ = m.pose(t)
    z = world.ground_z(xy[:, 0], xy[:, 1])
    return TruthPath(target.target_id, target.cls, t, np.column_stack([xy, z]))  # type: ignore[arg-type]


def _noisy(box: tuple[float, float, float, float], sigma: float, rng: np.random.Generator):
    b = np.array(box) + rng.normal(0.0, sigma, 4) if sigma > 0 else np.array(box)
    u0, u1 = sorted((b[0], b[2]))
    v0, v1 = sorted((b[1], b[3]))
    return (float(u0), float(v0), float(u1), float(v1))


def _false_alarm(camera: Camera, rng: np.random.Generator) -> tuple[str, tuple]:
    w, h = camera.intrinsics.width, camera.intrinsics.height
    cls = "vehicle" if rng.random() < 0.5 else "human"
    bw = rng.uniform(20, 70) if cls == "vehicle" else rng.uniform(4, 12)
    bh = 0.6 * bw if cls == "vehicle" else 3.0 * bw
    uc = rng.uniform(bw, w - bw)
    v1 = rng.uniform(0.35 * h, h - 5)
    return cls, (uc - bw / 2, max(v1 - bh, 0.0), uc + bw / 2, v1)


def site_world(site: Site) -> World:
    """The analytic world a sample site was generated from (its generator seed)."""
    doc = json.loads((site.root / "site.json").read_text("utf-8"))
    gen = doc.get("generator")
    if not isinstance(gen, dict) or "seed" not in gen:
        raise SiteError(f"{site.root} is not a generated sample site (no generator seed)")
    return make_world(int(gen["seed"]))


def make_scenario(site: Site, name: str, params: ScenarioParams | None = None) -> Scenario:
    """Build a scenario's detections and truth on a sample site.

    Parameters
    ----------
    site : Site
        A folder written by :func:`demtrack.samplesite.build.build_sample_site`.
    name : str
        A key of :data:`SCENARIOS`.
    params : ScenarioParams, optional
        Noise, misses, false alarms, seed.

    Raises
    ------
    SiteError
        Unknown scenario, or a site that is not a generated sample site.
    """
    if name not in SCENARIOS:
        raise SiteError(f"unknown scenario {name!r}; known: {', '.join(sorted(SCENARIOS))}")
    params = ScenarioParams() if params is None else params
    world = site_world(site)
    targets = SCENARIOS[name](world)
    return render_targets(site, world, name, targets, params)


def render_targets(
    site: Site,
    world: World,
    name: str,
    targets: Sequence[Target],
    params: ScenarioParams,
) -> Scenario:
    """Detections and truth for ``targets``, seen by the site's true cameras.

    Box sample points are cast against the site DEM (occlusion by trees and buildings),
    then edge noise, misses and false alarms are drawn from ``params``.
    """
    cameras = true_cameras(site)
    caster = RayCaster.from_dem(site.dem)
    t0 = min(tg.motion.t_start for tg in targets)
    t1 = max(tg.motion.t_end for tg in targets)
    frames = np.arange(0, int(math.floor((t1 - t0) * params.rate_hz)) + 1) / params.rate_hz + t0
    # Geometry first, all frames at once per (camera, target); random draws after, in a
    # fixed order, so the result depends on the seed only.
    geometry: dict[tuple[str, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    for tg in targets:
        active = (frames >= tg.motion.t_start) & (frames <= tg.motion.t_end)
        xy, head = tg.motion.pose(frames[active])
        pts = target_points(xy, head, tg.size_m, world)
        for sid, cam in cameras.items():
            boxes = np.full((len(frames), 4), np.nan)
            fraction = np.zeros(len(frames))
            in_view = np.zeros(len(frames), dtype=bool)
            if len(pts):
                boxes[active], fraction[active], in_view[active] = image_boxes(cam, caster, pts)
            geometry[(sid, tg.target_id)] = (boxes, fraction, in_view)
    rng = np.random.default_rng(params.seed)
    stats = dict.fromkeys(
        ("frames", "in_view", "detected", "partly_hidden", "hidden", "missed", "false_alarms"), 0
    )
    stats["frames"] = len(frames)
    detections: list[Detection] = []
    for i, t in enumerate(frames):
        for sid in sorted(cameras):
            for tg in targets:
                boxes, fraction, in_view = geometry[(sid, tg.target_id)]
                if not in_view[i]:
                    continue
                stats["in_view"] += 1
                if not np.isfinite(boxes[i, 0]) or fraction[i] < params.min_visible:
                    stats["hidden"] += 1
                    continue
                if rng.random() < params.p_miss:
                    stats["missed"] += 1
                    continue
                if fraction[i] < 0.999:
                    stats["partly_hidden"] += 1
                stats["detected"] += 1
                score = round(0.5 + 0.5 * float(fraction[i]) - 0.05 * float(rng.random()), 3)
                box = _noisy(tuple(boxes[i]), params.noise_px, rng)
                detections.append(Detection(float(t), sid, box, tg.cls, score))  # type: ignore[arg-type]
            for _ in range(rng.poisson(params.false_alarm_rate)):
                cls, box = _false_alarm(cameras[sid], rng)
                stats["false_alarms"] += 1
                score = round(float(rng.uniform(0.3, 0.7)), 3)
                detections.append(Detection(float(t), sid, box, cls, score))  # type: ignore[arg-type]
    truths = [_truth(tg, world) for tg in targets]
    return Scenario(name, params, detections, truths, stats)


# ---------------------------------------------------------------- truth files
def write_truth_json(path: str | Path, scenario: Scenario) -> None:
    """Write a scenario's ground truth (format ``demtrack.truth`` version 1)."""
    doc = {
        "format": "demtrack.truth",
        "version": 1,
        "scenario": scenario.name,
        "params": asdict(scenario.params),
        "frame": "site ENU (x east, y north, z up; m); t in s",
        "stats": scenario.stats,
        "targets": [
            {
                "target_id": tr.target_id,
                "class": tr.cls,
                "t_s": [round(float(x), 4) for x in tr.t_s],
                "p_enu": [[round(float(x), 4) for x in p] for p in tr.p_enu],
            }
            for tr in scenario.truths
        ],
    }
    Path(path).write_text(json.dumps(doc), "utf-8")


def read_truth_json(path: str | Path) -> list[TruthPath]:
    """Read :func:`write_truth_json` output back into true paths."""
    try:
        doc = json.loads(Path(path).read_text("utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise InputFileError(f"cannot read truth file {path}: {err}") from None
    if not isinstance(doc, dict) or doc.get("format") != "demtrack.truth":
        raise InputFileError(f"{path} is not a demtrack truth file")
    return [
        TruthPath(int(t["target_id"]), t["class"], np.array(t["t_s"]), np.array(t["p_enu"]))
        for t in doc["targets"]
    ]
