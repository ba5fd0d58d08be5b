"""Detections -> fixes: geolocate each box's foot on the site's terrain, in one batch.

The geolocation point of a detection is the bottom-centre of its box,
``u = (u_min + u_max) / 2, v = v_max`` (Collins et al. 1998). Its viewing ray is cast
against the DEM with :class:`~demtrack.core.geolocation.geolocate.Geolocator` (rule ``all``): every
terrain crossing, nearest first, with its 1-sigma horizontal uncertainty, and the road
rule's point when the site has roads. The trackers choose among them.

Foot offset
    The lowest image point of an object is the part of its footprint nearest the camera,
    not its centre. For a footprint ``L x W`` at a heading uniformly unknown relative to
    the line of sight, the centre lies on average ``(L + W) / pi`` farther along the
    line of sight (the mean of ``L/2 |cos a| + W/2 |sin a|``): 2.0 m for a 4.5 x 1.8 m
    car, 0.3 m for a person. Each fix's ray (origin and every hit) is moved that far
    horizontally along the ray's ground track, so the fix estimates the centre; heights
    stay those of the hits. Pass ``foot_offset_m={"vehicle": 0, "human": 0}`` for the
    paper's raw foot points.

Uncertainty
    Each hit keeps the geolocator's full horizontal covariance (pixel noise and DEM
    variance; long along a grazing ray, short across it) and adds the object's extent:
    the box marks some point of the footprint, not its centre (perspective, the roof
    leaning in the image, a side cut off by a crown), and a uniformly random point of an
    ``L x W`` rectangle at unknown heading lies ``(L^2 + W^2) / 24`` m^2 per axis from the
    centre (:func:`footprint_variances`: (0.99 m)^2 for a car, (0.14 m)^2 for a person).
    Along the ray it is at least the variance of the foot-to-centre distance over the
    heading. ``hit_sigma_m`` is the resulting worst-direction sigma.

Poses of the moment
    A sensor with a pose series in ``poses`` (or marked ``active`` in the site: a PTZ
    head whose pose comes from telemetry) is geolocated with the pose interpolated at
    each detection's own time (:meth:`~demtrack.core.camera.pose_series.PoseSeries.at`
    with the sensor's ``pose_latency_s`` and ``max_pose_gap_s``): pan, tilt, roll, zoom
    (the lens from the sensor's zoom table, else the ideal zoom), and on a moving
    platform position and attitude. A detection with no sample close enough, or whose
    zoom lies outside the sensor's calibration table, is counted ``no_pose`` and gives no
    fix: never a fix at a stale pose. Rays are made in the camera frame in one
    undistortion per sensor (per-pixel focal lengths for the ideal zoom, a whole lens per
    detection from a zoom table: ``ZoomTable.pixel_lenses``), each turned by its own
    rotation, and cast in one batch with the fixed sensors' rays
    (:mod:`~demtrack.core.geolocation.posed_rays`). Other sensors are geolocated at
    their stored pan and tilt, exactly as before.

Bad detections (unknown sensor, box beyond the image, time going backwards for its
sensor, no pose) are counted by reason and skipped; a ray that meets no terrain is
counted as ``no_hit`` and gives no fix. Nothing else is dropped.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..errors import TrackingError
from ..tracking.types import Detection, Fix
from .posed_rays import PosedView, posed_view_rays

if TYPE_CHECKING:  # types only: the site (a layer above) is what callers pass in
    from ..camera.pose_series import PoseSeries
    from ..site.folder import Sensor, Site

__all__ = [
    "FIX_REASONS",
    "FOOTPRINT_M",
    "FixReport",
    "build_fixes",
    "default_foot_offsets",
    "footprint_variances",
    "sensor_sizes",
]

#: Nominal footprint (length, width) of each class (m).
FOOTPRINT_M: dict[str, tuple[float, float]] = {"vehicle": (4.5, 1.8), "human": (0.5, 0.5)}
#: Reasons a detection gives no fix, in the order they are checked.
FIX_REASONS = ("unknown_sensor", "outside_image", "time_backwards", "no_pose", "no_hit")


def default_foot_offsets() -> dict[str, float]:
    """Mean distance (m) from an object's nearest footprint point to its centre, per class."""
    return {cls: (length + width) / math.pi for cls, (length, width) in FOOTPRINT_M.items()}


def footprint_variances() -> dict[str, tuple[float, float]]:
    """Extent variances (m^2) of each class: ``(along the ray, across it)``.

    Across: ``(L^2 + W^2) / 24``, the variance per axis of a uniform point of an
    ``L x W`` rectangle at uniformly random heading. Along: the larger of that and the
    variance of the foot-to-centre distance ``d(a) = L/2 |cos a| + W/2 |sin a|``, with
    ``E[d^2] = (L^2 + W^2) / 8 + L W / (2 pi)`` and ``E[d] = (L + W) / pi``.
    """
    out = {}
    for cls, (length, width) in FOOTPRINT_M.items():
        across = (length**2 + width**2) / 24.0
        mean = (length + width) / math.pi
        second = (length**2 + width**2) / 8.0 + length * width / (2.0 * math.pi)
        out[cls] = (max(second - mean * mean, across), across)
    return out


def sensor_sizes(site: Site) -> dict[str, tuple[int, int]]:
    """Sensor id -> image ``(width_px, height_px)``, for the detection readers."""
    return {
        sid: (s.head.intrinsics.width, s.head.intrinsics.height) for sid, s in site.sensors.items()
    }


@dataclass(frozen=True)
class FixReport:
    """What :func:`build_fixes` made and skipped.

    Parameters
    ----------
    n_detections : int
        Detections given.
    n_fixes : int
        Fixes made.
    counts : dict of str to int
        Skipped detections per reason of :data:`FIX_REASONS`.
    n_multi_hit : int
        Fixes whose ray met the terrain more than once (a crown, then the ground...).
    """

    n_detections: int
    n_fixes: int
    counts: dict[str, int] = field(default_factory=dict)
    n_multi_hit: int = 0

    def summary(self) -> str:
        """One line: fixes made and non-zero skip counts."""
        parts = [f"{k}={v}" for k, v in self.counts.items() if v]
        skipped = sum(self.counts.values())
        tail = f", skipped {skipped} ({', '.join(parts)})" if parts else ""
        return (
            f"{self.n_fixes} fixes from {self.n_detections} detections"
            f" ({self.n_multi_hit} with several terrain hits){tail}"
        )


def _check(
    detections: Sequence[Detection], site: Site, tol: float
) -> tuple[dict[str, list[int]], dict[str, int]]:
    """Group usable detection indices by sensor; count the rest by reason."""
    counts = dict.fromkeys(FIX_REASONS, 0)
    by_sensor: dict[str, list[int]] = {}
    last_t: dict[str, float] = {}
    for i, d in enumerate(detections):
        sensor = site.sensors.get(d.sensor)
        if sensor is None:
            counts["unknown_sensor"] += 1
            continue
        w, h = sensor.head.intrinsics.width, sensor.head.intrinsics.height
        u0, v0, u1, v1 = d.bbox
        if u0 < -0.5 - tol or v0 < -0.5 - tol or u1 > w - 0.5 + tol or v1 > h - 0.5 + tol:
            counts["outside_image"] += 1
            continue
        if d.sensor in last_t and d.t_s < last_t[d.sensor]:
            counts["time_backwards"] += 1
            continue
        last_t[d.sensor] = d.t_s
        by_sensor.setdefault(d.sensor, []).append(i)
    return by_sensor, counts


def build_fixes(
    site: Site,
    detections: Sequence[Detection],
    *,
    poses: Mapping[str, PoseSeries] | None = None,
    foot_offset_m: Mapping[str, float] | None = None,
    pixel_sigma_px: float = 1.0,
    edge_tolerance_px: float = 1.0,
) -> tuple[list[Fix], FixReport]:
    """Geolocate detections into :class:`Fix` values for the trackers.

    Parameters
    ----------
    site : Site
        DEM, roads and sensors (the cameras at their stored pan and tilt).
    detections : sequence of Detection
        In time order per sensor (a record older than its sensor's previous one is
        skipped as ``time_backwards``).
    poses : mapping of sensor id to PoseSeries, optional
        Pose telemetry: these sensors (and every ``active`` one, with or without a
        series) are geolocated at the pose of each detection's moment (module notes).
    foot_offset_m : mapping of class to float, optional
        Distance (m) to move each fix along its ray's ground track, from the box's foot to
        the object's centre (default :func:`default_foot_offsets`).
    pixel_sigma_px : float
        1-sigma error of the foot pixel, for each hit's uncertainty.
    edge_tolerance_px : float
        How far a box may reach past the image border.

    Returns
    -------
    fixes : list of Fix
        In the order of ``detections``; ``detection_index`` indexes ``detections``.
    report : FixReport
        What was skipped and why.
    """
    offsets = default_foot_offsets() if foot_offset_m is None else dict(foot_offset_m)
    for name, value in offsets.items():
        if not (math.isfinite(value) and value >= 0):
            raise TrackingError(f"foot offset for {name!r} must be >= 0 m, got {value}")
    by_sensor, counts = _check(detections, site, edge_tolerance_px)
    geo = site.geolocator(pixel_sigma_px=pixel_sigma_px)
    extent_var = footprint_variances()
    poses = {} if poses is None else poses
    views = []
    order: list[int] = []
    posed: list[tuple[Sensor, list[int]]] = []
    for sid, idx in by_sensor.items():
        if sid in poses or site.sensors[sid].active:
            posed.append((site.sensors[sid], idx))
            continue
        camera = site.sensors[sid].camera
        w, h = camera.intrinsics.width, camera.intrinsics.height
        boxes = np.array([detections[i].bbox for i in idx], dtype=np.float64).reshape(-1, 4)
        # The foot pixel, held on the image (a box may touch the border within tolerance).
        u = np.clip(0.5 * (boxes[:, 0] + boxes[:, 2]), -0.5, w - 0.5)
        v = np.clip(boxes[:, 3], -0.5, h - 0.5)
        views.append((camera, u, v))
        order += idx
    parts = geo.pixel_rays(views)
    for sensor, idx in posed:
        for view, rows in _posed_views(sensor, poses.get(sensor.id), detections, idx, counts):
            rays = posed_view_rays(view, geo.pixel_sigma_px)
            good = np.isfinite(rays[1]).all(axis=1) & np.isfinite(rays[3]).all(axis=1)
            if not good.all():  # no inverse of the lens at that zoom: no ray, no fix
                counts["no_pose"] += int(np.count_nonzero(~good))
                rays = tuple(r[good] for r in rays)  # type: ignore[assignment]
                rows = [r for r, g in zip(rows, good.tolist(), strict=True) if g]
            parts.append(rays)
            order += rows
    # One batch for every sensor: one ray cast, vectorised uncertainty and road rule.
    batch = geo.locate_ray_parts(parts)
    n_hits = batch.counts
    counts["no_hit"] += int(np.count_nonzero(n_hits == 0))
    n_multi = int(np.count_nonzero(n_hits > 1))
    cls = [detections[i].cls for i in order]
    offset = np.array([offsets.get(c, 0.0) for c in cls], dtype=np.float64)
    var_along, var_across = (
        np.array([extent_var.get(c, (0.0, 0.0))[k] for c in cls], dtype=np.float64) for k in (0, 1)
    )
    d = batch.directions_enu
    ground = d.copy()  # the ground tracks: (dx, dy, 0)
    ground[:, 2] = 0.0
    norm = np.linalg.norm(ground, axis=1)
    ray = np.repeat(np.arange(len(d)), n_hits)
    shift, cov = _centre_shift(ground, norm, offset, ray, batch.cov_en_m2, var_along, var_across)
    sigma = np.sqrt(np.linalg.eigvalsh(cov)[:, -1]) if len(cov) else np.zeros(0)
    hits_enu = batch.points_enu + shift[ray]
    origin_enu = batch.origins_enu + shift
    road_enu = batch.road_enu + shift
    has_road = batch.has_road
    # Only rays that met the terrain give a fix (their hits are contiguous already).
    keep = np.flatnonzero(n_hits > 0)
    kept = [order[r] for r in keep.tolist()]
    dets = [detections[i] for i in kept]
    fixes = Fix.from_arrays(
        [det.t_s for det in dets],
        [det.sensor for det in dets],
        [det.cls for det in dets],
        kept,
        origin_enu[keep],
        d[keep],
        np.concatenate(([0], np.cumsum(n_hits[keep]))),
        hits_enu,
        sigma,
        road_hit_enu=road_enu[keep],
        has_road=has_road[keep],
        score=[det.score for det in dets],
        hit_cov_en_m2=cov,
    )
    fixes.sort(key=lambda f: f.detection_index)
    return fixes, FixReport(len(detections), len(fixes), counts, n_multi)


def _posed_views(
    sensor: Sensor,
    series: PoseSeries | None,
    detections: Sequence[Detection],
    idx: list[int],
    counts: dict[str, int],
) -> list[tuple[PosedView, list[int]]]:
    """A posed sensor's detections as views, one per zoom; counts the ``no_pose`` ones.

    Returns each view with the detection indices of its pixels, in order.
    """
    if series is None:
        counts["no_pose"] += len(idx)
        return []
    head = sensor.head
    t = np.array([detections[i].t_s for i in idx], dtype=np.float64)
    at = series.at(t, max_gap_s=sensor.max_pose_gap_s, latency_s=sensor.pose_latency_s)
    sel = np.flatnonzero(at.ok)
    counts["no_pose"] += len(idx) - len(sel)
    if not len(sel):
        return []
    rot = at.camera_rotations(head)[sel]
    pos = at.positions(head)[sel]
    hfov = at.hfov_deg[sel]
    w, h = head.intrinsics.width, head.intrinsics.height
    boxes = np.array([detections[idx[k]].bbox for k in sel], dtype=np.float64).reshape(-1, 4)
    u = np.clip(0.5 * (boxes[:, 0] + boxes[:, 2]), -0.5, w - 0.5)
    v = np.clip(boxes[:, 3], -0.5, h - 0.5)
    if sensor.zoom is None and series is not None and series.has_zoom:
        # The ideal zoom of the calibrated lens: only the focal lengths change, so one
        # view with per-pixel focal lengths (one undistortion for all of them).
        base = head.intrinsics
        fx = 0.5 * base.width / np.tan(np.radians(hfov) / 2.0)
        view = PosedView(base, u, v, rot, pos, fx, fx * (base.fy / base.fx))
        return [(view, [idx[k] for k in sel.tolist()])]
    out = []
    unzoomed = np.flatnonzero(np.isnan(hfov))  # no zoom reported: the calibrated lens
    if len(unzoomed):
        view = PosedView(head.intrinsics, u[unzoomed], v[unzoomed], rot[unzoomed], pos[unzoomed])
        out.append((view, [idx[k] for k in sel[unzoomed].tolist()]))
    zoomed = np.flatnonzero(~np.isnan(hfov))
    if len(zoomed) and sensor.zoom is not None:
        # With a calibration table, a lens per detection in one view (one undistortion
        # with per-pixel coefficients, not an Intrinsics built and checked per zoom).
        lenses = sensor.zoom.pixel_lenses(hfov[zoomed], head.intrinsics)
        counts["no_pose"] += int(np.count_nonzero(~lenses.valid))  # off the table
        rows = zoomed[lenses.valid]
        if len(rows):
            lens = lenses.take(lenses.valid)
            view = PosedView(head.intrinsics, u[rows], v[rows], rot[rows], pos[rows], lenses=lens)
            out.append((view, [idx[k] for k in sel[rows].tolist()]))
    return out


def _centre_shift(
    ground: np.ndarray,
    norm: np.ndarray,
    offset: np.ndarray,
    ray: np.ndarray,
    cov_en_m2: np.ndarray,
    var_along: np.ndarray,
    var_across: np.ndarray,
    masked: bool | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Each ray's shift to the object's centre and each hit's covariance with the extent.

    Parameters
    ----------
    ground : ndarray, shape (n, 3)
        Ray directions with zero height: the ground tracks (not unit).
    norm : ndarray, shape (n,)
        Their lengths; at most 1e-9 (straight down) means no track: no shift, no along part.
    offset, var_along, var_across : ndarray, shape (n,)
        Foot-to-centre distance (m) and extent variances (m^2) per ray.
    ray : ndarray, int, shape (k,)
        The ray of each hit.
    cov_en_m2 : ndarray, shape (k, 2, 2)
        The geolocator's covariances (not modified).
    masked : bool, optional
        Force the general (masked) arithmetic or the all-tilted one; by default the
        all-tilted one when every ray has a track. Both give the same bits there.

    Returns
    -------
    shift : ndarray, shape (n, 3)
    cov : ndarray, shape (k, 2, 2)
    """
    tilted = norm > 1e-9
    cov = cov_en_m2 + var_across[ray][:, None, None] * np.eye(2)[None]
    # The centre's unknown distance behind the foot, along the ray's ground track.
    if masked is None:
        masked = not tilted.all()
    if not masked:  # the usual case: the same arithmetic without the masks
        shift = ground * (offset / norm)[:, None]
        a = (ground[:, :2] / norm[:, None])[ray]
        cov += (var_along - var_across)[ray][:, None, None] * (a[:, :, None] * a[:, None, :])
        return shift, cov
    shift = np.zeros_like(ground)
    shift[tilted] = ground[tilted] * (offset[tilted] / norm[tilted])[:, None]
    along = np.zeros((len(ground), 2))
    along[tilted] = ground[tilted, :2] / norm[tilted][:, None]
    bent = tilted[ray]
    a = along[ray[bent]]
    cov[bent] += (var_along - var_across)[ray[bent]][:, None, None] * (
        a[:, :, None] * a[:, None, :]
    )
    return shift, cov
