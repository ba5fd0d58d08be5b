"""Multi-sensor fusion: triangulate simultaneous rays of the same object.

Where two cameras see an object at (nearly) the same time their viewing rays cross near
it, and their closest approach locates it without the terrain model - free of DEM error
and of tree crowns. The point is the midpoint of the common perpendicular; the pair is
accepted only if the rays meet at a usable angle, pass close to each other, point forward,
and the point lies near a terrain hit of each ray (which rejects the "ghost" crossings of
one object's ray with another's). Pairs are chosen per sensor pair by minimum total miss
distance (:func:`scipy.optimize.linear_sum_assignment`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from .config import TrackerConfig
from .protocols import Measurement
from .types import Fix

__all__ = ["RayApproach", "closest_approach", "fuse_measurements", "triangulate_fixes"]


@dataclass(frozen=True, eq=False)
class RayApproach:
    """Closest approach of two rays.

    Parameters
    ----------
    p_enu : ndarray, shape (3,)
        Midpoint of the common perpendicular (m).
    miss_m : float
        Length of the common perpendicular (m).
    angle_rad : float
        Angle between the ray directions, in [0, pi].
    range_a_m, range_b_m : float
        Signed distances along each ray to the feet of the perpendicular (m; > 0 in front).
    """

    p_enu: np.ndarray
    miss_m: float
    angle_rad: float
    range_a_m: float
    range_b_m: float


def closest_approach(
    origin_a: np.ndarray, dir_a: np.ndarray, origin_b: np.ndarray, dir_b: np.ndarray
) -> RayApproach | None:
    """Closest approach of the lines ``o_a + s d_a`` and ``o_b + t d_b`` (None if parallel).

    Parameters
    ----------
    origin_a, dir_a, origin_b, dir_b : ndarray, shape (3,)
        Origins (m) and directions (any length) in one frame.
    """
    oa = np.asarray(origin_a, dtype=np.float64)
    ob = np.asarray(origin_b, dtype=np.float64)
    da = np.asarray(dir_a, dtype=np.float64)
    db = np.asarray(dir_b, dtype=np.float64)
    da = da / np.linalg.norm(da)
    db = db / np.linalg.norm(db)
    b = float(da @ db)
    denom = 1.0 - b * b
    if denom < 1e-12:
        return None
    w0 = oa - ob
    d = float(da @ w0)
    e = float(db @ w0)
    s = (b * e - d) / denom
    t = (e - b * d) / denom
    pa = oa + s * da
    pb = ob + t * db
    angle = math.acos(max(-1.0, min(1.0, b)))
    return RayApproach(0.5 * (pa + pb), float(np.linalg.norm(pa - pb)), angle, s, t)


def _near_a_hit(p: np.ndarray, fix: Fix, gate_sigma: float) -> bool:
    if fix.n_hits == 0:
        return False
    dist = np.linalg.norm(fix.hits_enu[:, :2] - p[:2], axis=1)
    return bool(np.any(dist <= gate_sigma * fix.hit_sigma_m + 1.0))


def triangulate_fixes(fix_a: Fix, fix_b: Fix, config: TrackerConfig) -> Fix | None:
    """Triangulate two fixes of one object; None if they fail the checks.

    Checks: same class, different sensors, rays at least ``config.fusion_min_angle_deg``
    apart (and as far from parallel), common perpendicular at most
    ``config.fusion_max_miss_m`` long with both feet in front of the cameras, and its
    midpoint within ``config.fusion_hit_gate_sigma`` hit sigmas plus 1 m (horizontally)
    of a terrain hit of each ray.

    The result has one hit (the midpoint) whose covariance combines, across each ray's
    ground track, the larger of the ray's angular error (``config.ray_sigma_rad`` times
    range) and the fix's own across-ray sigma (the object's extent), plus half the miss
    distance; its sigma is that covariance's worst direction. Its origin
    and direction are ``fix_a``'s, its sensor is
    ``"a+b"`` (sorted names), its time the mean, its detection index ``fix_a``'s. It has
    a road hit (the midpoint) when either input had one.
    """
    out = _triangulate(fix_a, fix_b, config)
    return None if out is None else out[0]


def _triangulate(fix_a: Fix, fix_b: Fix, config: TrackerConfig) -> tuple[Fix, float] | None:
    """Do :func:`triangulate_fixes`, also returning the miss distance (m)."""
    if fix_a.cls != fix_b.cls or fix_a.sensor == fix_b.sensor:
        return None
    ra = closest_approach(
        fix_a.origin_enu, fix_a.direction_enu, fix_b.origin_enu, fix_b.direction_enu
    )
    if ra is None:
        return None
    sin_angle = math.sin(ra.angle_rad)
    if sin_angle < math.sin(math.radians(config.fusion_min_angle_deg)):
        return None
    if ra.miss_m > config.fusion_max_miss_m or ra.range_a_m <= 0 or ra.range_b_m <= 0:
        return None
    gate = config.fusion_hit_gate_sigma
    if not (_near_a_hit(ra.p_enu, fix_a, gate) and _near_a_hit(ra.p_enu, fix_b, gate)):
        return None
    sa = config.ray_sigma_rad * ra.range_a_m
    sb = config.ray_sigma_rad * ra.range_b_m
    worst = math.sqrt(0.5 * (sa * sa + sb * sb)) / sin_angle
    # across each ray: the ray's angular error or the fix's own across-ray sigma (the
    # object's extent), whichever is larger
    sa = max(sa, math.sqrt(_across_var(fix_a, _across(fix_a), ra.p_enu)))
    sb = max(sb, math.sqrt(_across_var(fix_b, _across(fix_b), ra.p_enu)))
    cov = _triangulation_cov(fix_a, fix_b, sa, sb, worst)
    cov += (max(0.5 * ra.miss_m, 0.05) ** 2) * np.eye(2)
    sigma = math.sqrt(float(np.linalg.eigvalsh(cov)[-1]))
    road = ra.p_enu if (fix_a.road_hit_enu is not None or fix_b.road_hit_enu is not None) else None
    scores = [s for s in (fix_a.score, fix_b.score) if s is not None]
    fused = Fix(
        t_s=0.5 * (fix_a.t_s + fix_b.t_s),
        sensor="+".join(sorted((fix_a.sensor, fix_b.sensor))),
        cls=fix_a.cls,
        detection_index=fix_a.detection_index,
        origin_enu=fix_a.origin_enu,
        direction_enu=fix_a.direction_enu,
        hits_enu=ra.p_enu[None, :],
        hit_sigma_m=np.array([sigma]),
        road_hit_enu=road,
        score=max(scores) if scores else None,
        hit_cov_en_m2=cov[None],
    )
    return fused, ra.miss_m


def _across(fix: Fix) -> np.ndarray:
    """Unit horizontal normal (2,) of the fix's ray ground track (x for a vertical ray)."""
    g = fix.direction_enu[:2]
    norm = float(np.hypot(g[0], g[1]))
    return np.array([1.0, 0.0]) if norm < 1e-9 else np.array([-g[1], g[0]]) / norm


def _across_var(fix: Fix, n: np.ndarray, p_enu: np.ndarray) -> float:
    """Variance (m^2) across the ray (unit ``n``) of the fix's hit nearest ``p_enu``.

    A hit's covariance holds what pins the *object's centre* across the ray: pixel
    noise and the footprint's extent (the box's centre column is some point of the
    object, not its centre). 0 for a fix without hits.
    """
    if fix.n_hits == 0:
        return 0.0
    j = int(np.argmin(np.sum((fix.hits_enu[:, :2] - p_enu[:2]) ** 2, axis=1)))
    return float(n @ fix.hit_covariances()[j] @ n)


def _triangulation_cov(fix_a: Fix, fix_b: Fix, sa: float, sb: float, worst: float) -> np.ndarray:
    """Horizontal covariance (2, 2) of a two-ray triangulation (m^2).

    Each ray pins the point across its own ground track to ``sa`` / ``sb`` (m: the larger
    of the ray's angular error ``sigma_ray * range`` and its fix's own across-ray sigma,
    which holds the footprint's extent - two cameras see different parts of a car, so
    the rays meet near, not at, its centre) and says nothing along it; the information
    of the two adds. Rays whose ground tracks are (nearly) parallel leave a direction
    unpinned, so a weak isotropic prior of the rays' worst-direction sigma ``worst`` (m,
    from the angular errors alone) bounds it.
    """
    info = np.eye(2) / (worst * worst)
    for fix, s in ((fix_a, sa), (fix_b, sb)):
        g = fix.direction_enu[:2]
        norm = float(np.hypot(g[0], g[1]))
        if norm < 1e-9:  # a vertical ray pins both directions
            info += np.eye(2) / (s * s)
            continue
        n = np.array([-g[1], g[0]]) / norm
        info += np.outer(n, n) / (s * s)
    cov = np.linalg.inv(info)
    return 0.5 * (cov + cov.T)


def fuse_measurements(
    measurements: Sequence[Measurement], config: TrackerConfig
) -> list[Measurement]:
    """Replace same-object pairs from different sensors by their triangulation.

    Parameters
    ----------
    measurements : sequence of Measurement
        Single-sensor measurements of one step (times within ``config.step_window_s``).
    config : TrackerConfig
        Fusion thresholds.

    Returns
    -------
    list of Measurement
        Fused measurements (in time order) followed by the unpaired ones (input order).
        Each input is used at most once; with three or more sensors, sensor pairs are
        taken in name order.
    """
    by_sensor: dict[str, list[int]] = {}
    for i, m in enumerate(measurements):
        by_sensor.setdefault(m.fix.sensor, []).append(i)
    names = sorted(by_sensor)
    used: set[int] = set()
    fused: list[Measurement] = []
    for ia, sa in enumerate(names):
        for sb in names[ia + 1 :]:
            left = [i for i in by_sensor[sa] if i not in used]
            right = [j for j in by_sensor[sb] if j not in used]
            if not left or not right:
                continue
            cost = np.full((len(left), len(right)), np.inf)
            cand: dict[tuple[int, int], Fix] = {}
            for r, i in enumerate(left):
                for c, j in enumerate(right):
                    fa, fb = measurements[i].fix, measurements[j].fix
                    if abs(fa.t_s - fb.t_s) > config.step_window_s:
                        continue
                    tri = _triangulate(fa, fb, config)
                    if tri is not None:
                        cand[(r, c)], cost[r, c] = tri
            if not cand:
                continue
            finite = np.where(np.isfinite(cost), cost, 1e18)
            for r, c in zip(*linear_sum_assignment(finite), strict=True):
                if (r, c) in cand:
                    i, j = left[r], right[c]
                    used.update((i, j))
                    mi, mj = measurements[i], measurements[j]
                    fused.append(
                        Measurement(cand[(r, c)], mi.indices + mj.indices, mi.sensors + mj.sensors)
                    )
    fused.sort(key=lambda m: m.t_s)
    return fused + [m for i, m in enumerate(measurements) if i not in used]
