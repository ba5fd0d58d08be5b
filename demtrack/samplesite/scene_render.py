"""Rendering targets into detections: what each camera would really report, frame by frame.

A target is a box (:data:`SIZES_M`); its image box is the bounding box of the projections
of the sample points on its surface (:func:`target_points`) that the camera sees: a ray
from the optical centre to each point is cast against the site DEM (a first-return
surface, so tree crowns and roofs occlude), and points behind the surface are dropped.
Boxes then get pixel noise on each edge; detections are missed at random and false alarms
appear at random (:class:`ScenarioParams`). The same code serves fixed cameras (one
camera for every frame: :func:`render_targets`) and moving ones (a camera per frame, from
a pan-tilt-zoom head's true pose: :func:`render_frame`): occlusion depends only on the
optical centre, the field of view on the whole pose.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from demtrack.core.camera.pinhole import Camera
from demtrack.core.errors import SiteError
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import Detection, TruthPath

from .routes import Motion
from .world import World, make_world

if TYPE_CHECKING:
    from demtrack.core.camera.pose_series import PoseSeries

__all__ = [
    "FrameGeometry",
    "SIZES_M",
    "STAT_KEYS",
    "Scenario",
    "ScenarioParams",
    "Target",
    "draw_frame",
    "frame_times",
    "image_boxes",
    "line_of_sight",
    "render_frame",
    "render_targets",
    "site_world",
    "target_points",
    "true_cameras",
    "true_yaws",
    "truth_path",
]

#: Nominal box of each class: (length along heading, width, height) in metres.
SIZES_M: dict[str, tuple[float, float, float]] = {
    "vehicle": (4.5, 1.8, 1.5),
    "human": (0.5, 0.5, 1.8),
}
#: The counts of :attr:`Scenario.stats`, in their order. ``target_frames`` counts
#: (target, frame) pairs while the target exists, ``target_frames_seen`` those in which
#: some camera would detect it (in its field of view and visible enough; before misses).
STAT_KEYS = (
    "frames",
    "in_view",
    "detected",
    "partly_hidden",
    "hidden",
    "missed",
    "false_alarms",
    "target_frames",
    "target_frames_seen",
)


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
        Counts (:data:`STAT_KEYS`): frames, in view, detected, partly hidden, hidden,
        missed, false alarms, target frames, target frames seen.
    poses : dict of str to PoseSeries
        The pose telemetry each moving sensor reported (pan, tilt, hfov; stamped on the
        telemetry clock); empty for scenarios seen by fixed cameras.
    """

    name: str
    params: ScenarioParams
    detections: list[Detection]
    truths: list[TruthPath]
    stats: dict[str, int] = field(default_factory=dict)
    poses: dict[str, PoseSeries] = field(default_factory=dict)

    @property
    def in_view_share(self) -> float:
        """Share of the targets' time some camera would detect them (NaN if no frames)."""
        n = self.stats.get("target_frames", 0)
        return self.stats.get("target_frames_seen", 0) / n if n else float("nan")


def site_world(site: Site) -> World:
    """The analytic world a sample site was generated from (its generator seed)."""
    doc = json.loads((site.root / "site.json").read_text("utf-8"))
    gen = doc.get("generator")
    if not isinstance(gen, dict) or "seed" not in gen:
        raise SiteError(f"{site.root} is not a generated sample site (no generator seed)")
    return make_world(int(gen["seed"]))


def true_yaws(site: Site) -> dict[str, float]:
    """Sensor id -> true mount yaw (degrees) from the site's ``truth.json`` (if present)."""
    truth_path = site.root / "truth.json"
    if not truth_path.is_file():
        return {}
    doc = json.loads(truth_path.read_text("utf-8"))
    return {k: float(v["true_mount_yaw_deg"]) for k, v in doc.get("sensors", {}).items()}


def true_cameras(site: Site) -> dict[str, Camera]:
    """Each sensor's camera with the true mount yaw from ``truth.json`` (if present)."""
    yaws = true_yaws(site)
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


def line_of_sight(caster: RayCaster, origin_enu: np.ndarray, points: np.ndarray) -> np.ndarray:
    """True where the DEM surface does not hide ``points`` (n, 3) from ``origin_enu`` (m).

    A surface crossing more than 1 m before the point hides it; the margin absorbs the
    DEM's centimetres of error where a ray grazes the ground at a target's feet. No
    angular index: for these scattered target points building one costs as much CPU as it
    saves, and on a cold machine its kernels cost a minute to compile.
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not len(pts):
        return np.zeros(0, dtype=bool)
    origin = np.asarray(origin_enu, dtype=np.float64)
    vec = pts - origin
    dist = np.linalg.norm(vec, axis=1)
    hits = caster.cast(
        np.broadcast_to(origin, vec.shape).copy(),
        vec,
        np.maximum(dist - 1.0, 0.0),
        mode="first",
        coherent=False,
    )
    return hits.counts == 0


def image_boxes(
    camera: Camera,
    caster: RayCaster | None,
    points: np.ndarray,
    border_px: float = 2.0,
    clear: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Image boxes of the visible parts of targets, and the fractions seen.

    Parameters
    ----------
    camera : Camera
        The true camera.
    caster : RayCaster or None
        The site DEM (first-return surface); may be None when ``clear`` is given.
    points : ndarray, shape (f, k, 3)
        Sample points of ``f`` target poses (:func:`target_points`).
    border_px : float
        A box this close to the image border is cut by it, and is not reported.
    clear : ndarray of bool, shape (f, k), optional
        The points' line of sight from the camera's optical centre
        (:func:`line_of_sight`), when known already (a moving head keeps its centre);
        otherwise the points on the image are cast against the DEM here.

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
    if clear is not None:
        seen = on_image & np.asarray(clear, dtype=bool).reshape(-1)
    else:
        if caster is None:
            raise SiteError("image_boxes needs a caster or the points' line of sight")
        seen = np.zeros(f * k, dtype=bool)
        idx = np.flatnonzero(on_image)
        if idx.size:
            seen[idx] = line_of_sight(caster, camera.position_enu, flat[idx])
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


#: One (sensor, target) pair's geometry at one frame: image box (4,) (NaN: none),
#: fraction of the target seen, and whether some point falls on the image.
FrameGeometry = tuple[np.ndarray, float, bool]


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


def _detectable(geom: FrameGeometry, params: ScenarioParams) -> bool:
    box, fraction, _ = geom
    return bool(np.isfinite(box[0])) and fraction >= params.min_visible


def draw_frame(
    t_s: float,
    cameras: Mapping[str, Camera],
    targets: Sequence[Target],
    geometry: Mapping[tuple[str, int], FrameGeometry],
    params: ScenarioParams,
    rng: np.random.Generator,
    stats: dict[str, int],
) -> list[Detection]:
    """One frame's detections from its geometry: box noise, misses and false alarms.

    The random draws come in a fixed order (sensor id, then target, then the sensor's
    false alarms), so a scenario depends on its seed only. ``geometry`` holds the pairs
    whose target exists at ``t_s``; ``stats`` (:data:`STAT_KEYS`) is updated in place.
    """
    detections: list[Detection] = []
    for tg in targets:
        keys = [(sid, tg.target_id) for sid in cameras]
        pairs = [geometry[key] for key in keys if key in geometry]
        if pairs:
            stats["target_frames"] += 1
            stats["target_frames_seen"] += any(_detectable(g, params) for g in pairs)
    for sid in sorted(cameras):
        for tg in targets:
            geom = geometry.get((sid, tg.target_id))
            if geom is None or not geom[2]:
                continue
            box, fraction, _ = geom
            stats["in_view"] += 1
            if not _detectable(geom, params):
                stats["hidden"] += 1
                continue
            if rng.random() < params.p_miss:
                stats["missed"] += 1
                continue
            if fraction < 0.999:
                stats["partly_hidden"] += 1
            stats["detected"] += 1
            score = round(0.5 + 0.5 * float(fraction) - 0.05 * float(rng.random()), 3)
            noisy = _noisy(tuple(box), params.noise_px, rng)
            detections.append(Detection(float(t_s), sid, noisy, tg.cls, score))  # type: ignore[arg-type]
        for _ in range(rng.poisson(params.false_alarm_rate)):
            cls, fa_box = _false_alarm(cameras[sid], rng)
            stats["false_alarms"] += 1
            score = round(float(rng.uniform(0.3, 0.7)), 3)
            detections.append(Detection(float(t_s), sid, fa_box, cls, score))  # type: ignore[arg-type]
    return detections


def render_frame(
    t_s: float,
    cameras: Mapping[str, Camera],
    targets: Sequence[Target],
    world: World,
    caster: RayCaster,
    params: ScenarioParams,
    rng: np.random.Generator,
    stats: dict[str, int] | None = None,
    clear: Mapping[tuple[str, int], np.ndarray] | None = None,
) -> tuple[list[Detection], dict[tuple[str, int], FrameGeometry]]:
    """The detections each camera would produce at ``t_s``, from the targets' true states.

    Parameters
    ----------
    t_s : float
        Frame time (s, the scenario clock).
    cameras : mapping of str to Camera
        Each sensor's true camera at ``t_s`` (a moving head: its pose and zoom then).
    targets : sequence of Target
        Those not moving at ``t_s`` (before their start, after their end) are absent.
    world : World
        The true ground under the targets.
    caster : RayCaster
        The site DEM, for occlusion.
    params : ScenarioParams
        Noise, misses, false alarms.
    rng : numpy.random.Generator
        Drawn from in :func:`draw_frame`'s order.
    stats : dict, optional
        Counts (:data:`STAT_KEYS`) to update in place.
    clear : mapping of (sensor, target id) to ndarray of bool (k,), optional
        Each pair's line of sight at ``t_s``, when already known.

    Returns
    -------
    detections : list of Detection
        In sensor order, targets first, then false alarms.
    geometry : dict of (sensor, target id) to FrameGeometry
        The noise-free boxes, fractions seen and in-view flags.
    """
    geometry: dict[tuple[str, int], FrameGeometry] = {}
    for tg in targets:
        if not tg.motion.t_start <= t_s <= tg.motion.t_end:
            continue
        xy, head = tg.motion.pose(np.array([t_s]))
        pts = target_points(xy, head, tg.size_m, world)
        for sid, cam in cameras.items():
            mask = None if clear is None else clear[(sid, tg.target_id)][None]
            boxes, fraction, in_view = image_boxes(cam, caster, pts, clear=mask)
            geometry[(sid, tg.target_id)] = (boxes[0], float(fraction[0]), bool(in_view[0]))
    counts = dict.fromkeys(STAT_KEYS, 0) if stats is None else stats
    return draw_frame(t_s, cameras, targets, geometry, params, rng, counts), geometry


def frame_times(targets: Sequence[Target], rate_hz: float) -> np.ndarray:
    """The frame clock (s): from the first target's start to the last one's end."""
    t0 = min(tg.motion.t_start for tg in targets)
    t1 = max(tg.motion.t_end for tg in targets)
    return np.arange(0, int(math.floor((t1 - t0) * rate_hz)) + 1) / rate_hz + t0


def truth_path(target: Target, world: World, dt_s: float = 0.05) -> TruthPath:
    """A target's true footprint centre on the true ground, every ``dt_s`` seconds."""
    m = target.motion
    t = np.arange(m.t_start, m.t_end + 1e-9, dt_s)
    xy, _ = m.pose(t)
    z = world.ground_z(xy[:, 0], xy[:, 1])
    return TruthPath(target.target_id, target.cls, t, np.column_stack([xy, z]))  # type: ignore[arg-type]


def render_targets(
    site: Site,
    world: World,
    name: str,
    targets: Sequence[Target],
    params: ScenarioParams,
) -> Scenario:
    """Detections and truth for ``targets``, seen by the site's true (fixed) cameras.

    Box sample points are cast against the site DEM (occlusion by trees and buildings),
    then edge noise, misses and false alarms are drawn from ``params``.
    """
    cameras = true_cameras(site)
    caster = RayCaster.from_dem(site.dem)
    frames = frame_times(targets, params.rate_hz)
    # Geometry first, all frames at once per (camera, target); random draws after, in a
    # fixed order, so the result depends on the seed only.
    geometry: dict[tuple[str, int], tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    actives = {}
    for tg in targets:
        active = (frames >= tg.motion.t_start) & (frames <= tg.motion.t_end)
        actives[tg.target_id] = active
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
    stats = dict.fromkeys(STAT_KEYS, 0)
    stats["frames"] = len(frames)
    detections: list[Detection] = []
    for i, t in enumerate(frames):
        at_i = {
            key: (g[0][i], float(g[1][i]), bool(g[2][i]))
            for key, g in geometry.items()
            if actives[key[1]][i]
        }
        detections += draw_frame(float(t), cameras, targets, at_i, params, rng, stats)
    truths = [truth_path(tg, world) for tg in targets]
    return Scenario(name, params, detections, truths, stats)
