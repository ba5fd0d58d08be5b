"""Multi-sensor fusion: triangulate simultaneous rays of the same object.

Where two cameras see an object at (nearly) the same time their viewing rays cross near
it, and their closest approach locates it without the terrain model - free of DEM error
and of tree crowns. The point is the midpoint of the common perpendicular; the pair is
accepted only if the rays meet at a usable angle, pass close to each other, point forward,
and the point lies near a terrain hit of each ray (which rejects the "ghost" crossings of
one object's ray with another's). Pairs are chosen per sensor pair by minimum total
inconsistency (:func:`scipy.optimize.linear_sum_assignment`): the squared Mahalanobis
distances of the point to each ray's nearest terrain hit, under that hit's covariance
(:func:`pair_cost`). Rays of two different objects can cross within the miss limit (a
ghost), but then the crossing lies several along-ray sigmas from the hits of both; the
miss distance alone (the old cost) cannot tell a ghost from the true pair, and among
many objects (the console's dense replay) about 1 % of the pairs made were ghosts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from .config import TrackerConfig
from .fusion_kernels import screen_pairs_kernel, triangulation_cov_kernel
from .protocols import Measurement
from .types import CLASSES, Fix

__all__ = [
    "RayApproach",
    "closest_approach",
    "fuse_measurements",
    "pair_cost",
    "triangulate_fixes",
]


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


def _hit_d2(p_enu: np.ndarray, fix: Fix) -> float:
    """Smallest squared Mahalanobis distance of ``p_enu`` (horizontal) to a hit of ``fix``."""
    if fix.n_hits == 0:
        return math.inf
    d = fix.hits_enu[:, :2] - np.asarray(p_enu, dtype=np.float64)[:2]
    c = fix.hit_covariances()
    return float(np.min(np.einsum("ki,kij,kj->k", d, np.linalg.inv(c), d)))


def pair_cost(p_enu: np.ndarray, fix_a: Fix, fix_b: Fix) -> float:
    """Inconsistency of a triangulated point with the two fixes' terrain hits.

    The sum over both fixes of the squared Mahalanobis distance (horizontal, under the
    hit's covariance) from ``p_enu`` to the fix's nearest hit: about chi-square with 4
    degrees of freedom for the true pair, large for a ghost crossing of two objects' rays.
    """
    return _hit_d2(p_enu, fix_a) + _hit_d2(p_enu, fix_b)


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


def _triangulate(
    fix_a: Fix, fix_b: Fix, config: TrackerConfig, screened: bool = False
) -> tuple[Fix, float] | None:
    """Do :func:`triangulate_fixes`, also returning the miss distance (m).

    ``screened``: :func:`_screen_pairs` found the pair clear of every threshold, so the
    hit checks are not repeated (the numbers are computed exactly as without it).
    """
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
    if not screened and not (
        _near_a_hit(ra.p_enu, fix_a, gate) and _near_a_hit(ra.p_enu, fix_b, gate)
    ):
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
    args = (
        0.5 * (fix_a.t_s + fix_b.t_s),
        "+".join(sorted((fix_a.sensor, fix_b.sensor))),
        fix_a.cls,
        fix_a.detection_index,
        fix_a.origin_enu,
        fix_a.direction_enu,
        ra.p_enu[None, :],
        np.array([sigma]),
        road,
        max(scores) if scores else None,
        cov[None],
    )
    return _fused_fix(*args), ra.miss_m


def _fused_fix(
    t_s: float,
    sensor: str,
    cls: str,
    index: int,
    origin: np.ndarray,
    direction: np.ndarray,
    hits: np.ndarray,
    sigma: np.ndarray,
    road: np.ndarray | None,
    score: float | None,
    cov: np.ndarray,
) -> Fix:
    """The triangulated :class:`Fix`, as its public constructor would make it.

    The inputs come from checked fixes and are finite by construction; what the
    constructor would do to them (copy, renormalise the direction, symmetrise the
    covariance - already symmetric) is done here without its checks. Anything unusual
    (a non-finite value, a covariance that is not positive definite) goes through the
    constructor, which says what is wrong.
    """
    det = cov[0, 0, 0] * cov[0, 1, 1] - cov[0, 0, 1] * cov[0, 1, 0]
    if not (
        math.isfinite(t_s)
        and np.isfinite(hits).all()
        and math.isfinite(float(sigma[0]))
        and sigma[0] > 0
        and np.isfinite(cov).all()
        and cov[0, 0, 1] == cov[0, 1, 0]
        and cov[0, 0, 0] > 0
        and det > 0
    ):
        return Fix(t_s, sensor, cls, index, origin, direction, hits, sigma, road, score, cov)  # type: ignore[arg-type]
    unit = np.array(direction, dtype=np.float64)
    unit /= float(np.linalg.norm(unit))
    road_copy = None if road is None else np.array(road, dtype=np.float64)
    hits = np.array(hits, dtype=np.float64)
    arrays = (unit, road_copy, hits, sigma, cov)
    for a in arrays:
        if a is not None:
            a.setflags(write=False)
    return Fix._trusted(t_s, sensor, cls, index, origin, unit, hits, sigma, road_copy, score, cov)  # type: ignore[arg-type]


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

    Notes
    -----
    The checks of :func:`triangulate_fixes` are screened for all pairs of a sensor pair
    at once (:func:`_screen_pairs`); only pairs within round-off of a threshold go
    through the scalar checks, and only the pairs finally matched are triangulated.
    """
    by_sensor: dict[str, list[int]] = {}
    for i, m in enumerate(measurements):
        by_sensor.setdefault(m.fix.sensor, []).append(i)
    names = sorted(by_sensor)
    used: set[int] = set()
    fused: list[Measurement] = []
    if len(names) < 2:
        return list(measurements)
    # each sensor's arrays made once (a sensor takes part in several sensor pairs)
    arrays: dict[str, _Arrays] = {}

    def rows_of(name: str) -> tuple[list[int], _Arrays]:
        every = by_sensor[name]
        if name not in arrays:
            arrays[name] = _fix_arrays([measurements[i].fix for i in every])
        keep = [k for k, i in enumerate(every) if i not in used]
        if len(keep) == len(every):
            return every, arrays[name]
        rows = np.array(keep, dtype=np.intp)
        return [every[k] for k in keep], tuple(a[rows] for a in arrays[name])

    for ia, sa in enumerate(names):
        for sb in names[ia + 1 :]:
            left, pre_a = rows_of(sa)
            right, pre_b = rows_of(sb)
            if not left or not right:
                continue
            fa = [measurements[i].fix for i in left]
            fb = [measurements[j].fix for j in right]
            for r, c, tri in _pair_vectorised(fa, fb, config, (pre_a, pre_b)):
                i, j = left[r], right[c]
                used.update((i, j))
                mi, mj = measurements[i], measurements[j]
                fused.append(Measurement(tri[0], mi.indices + mj.indices, mi.sensors + mj.sensors))
    fused.sort(key=lambda m: m.t_s)
    return fused + [m for i, m in enumerate(measurements) if i not in used]


def _pair_scalar(
    fa: Sequence[Fix], fb: Sequence[Fix], config: TrackerConfig
) -> list[tuple[int, int, tuple[Fix, float]]]:
    """Matched ``(row, col, (fused fix, miss))``: every pair triangulated, then assigned.

    The assignment minimises the total :func:`pair_cost`. The pair-by-pair reference of
    :func:`_pair_vectorised` (which the fusion uses: with the compiled screen it is the
    faster one even for a single pair).
    """
    cost = np.full((len(fa), len(fb)), np.inf)
    cand: dict[tuple[int, int], tuple[Fix, float]] = {}
    for r, a in enumerate(fa):
        for c, b in enumerate(fb):
            if abs(a.t_s - b.t_s) > config.step_window_s:
                continue
            tri = _triangulate(a, b, config)
            if tri is not None:
                cand[(r, c)] = tri
                cost[r, c] = pair_cost(tri[0].hits_enu[0], a, b)
    if not cand:
        return []
    finite = np.where(np.isfinite(cost), cost, 1e18)
    rows, cols = linear_sum_assignment(finite)
    return [
        (r, c, cand[(r, c)])
        for r, c in zip(rows.tolist(), cols.tolist(), strict=True)
        if (r, c) in cand
    ]


def _pair_vectorised(
    fa: Sequence[Fix],
    fb: Sequence[Fix],
    config: TrackerConfig,
    pre: tuple[_Arrays, _Arrays] | None = None,
) -> list[tuple[int, int, tuple[Fix, float]]]:
    """:func:`_pair_scalar` with the checks and the matched triangulations vectorised.

    ``pre``: :func:`_fix_arrays` of ``fa`` and of ``fb``, when the caller has them.
    """
    out: list[tuple[int, int, tuple[Fix, float]]] = []
    screen = _screen_pairs(fa, fb, config, pre)
    ok = np.isfinite(screen.cost)
    if not ok.any():
        return out
    finite = np.where(ok, screen.cost, 1e18)
    rows, cols = linear_sum_assignment(finite)
    keep = ok[rows, cols]
    rows, cols = rows[keep], cols[keep]
    clear = screen.clear[rows, cols]
    made = dict(
        zip(
            zip(rows[clear].tolist(), cols[clear].tolist(), strict=True),
            _triangulate_screened(fa, fb, rows[clear], cols[clear], screen, config),
            strict=True,
        )
    )
    for r, c in zip(rows.tolist(), cols.tolist(), strict=True):
        tri = made.get((r, c)) or _triangulate(fa[r], fb[c], config)
        if tri is not None:  # None: only a pair at a threshold's round-off
            out.append((r, c, tri))
    return out


#: Slack (m, or unitless for the angle terms) within which a vectorised check is redone
#: by the scalar one, so round-off never changes which pairs are accepted.
_SCREEN_TOL = 1e-6


#: A sequence of fixes' arrays for :func:`_screen_pairs` (see :func:`_fix_arrays`).
_Arrays = tuple[np.ndarray, ...]


def _fix_arrays(fixes: Sequence[Fix]) -> _Arrays:
    """Origins (n, 3), directions (n, 3), times (n,), class codes (n,) and padded hits.

    The codes number the classes in name order (only equality matters); the hits are
    :func:`_padded_hits`, whose NaN padding the kernels skip, so rows taken from a wider
    padding give the same answers.
    """
    origin = np.array([f.origin_enu for f in fixes])
    direction = np.array([f.direction_enu for f in fixes])
    t_s = np.array([f.t_s for f in fixes])
    code = np.array([CLASSES.index(f.cls) for f in fixes], dtype=np.int64)
    return (origin, direction, t_s, code, *_padded_hits(fixes))


def _padded_hits(fixes: Sequence[Fix]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Hits (n, k, 2), their sigmas (n, k) and covariances (n, k, 2, 2), NaN-padded."""
    counts = {f.n_hits for f in fixes}
    if len(counts) == 1 and 0 not in counts and all(f.hit_cov_en_m2 is not None for f in fixes):
        # every fix with the same number of hits, none padded: stack them whole
        xy = np.array([f.hits_enu for f in fixes])[:, :, :2].copy()
        sig = np.array([f.hit_sigma_m for f in fixes])
        cov = np.array([f.hit_cov_en_m2 for f in fixes])
        return xy, sig, cov
    k = max((f.n_hits for f in fixes), default=0)
    xy = np.full((len(fixes), max(k, 1), 2), np.nan)
    sig = np.full((len(fixes), max(k, 1)), np.nan)
    cov = np.full((len(fixes), max(k, 1), 2, 2), np.nan)
    for r, f in enumerate(fixes):
        xy[r, : f.n_hits] = f.hits_enu[:, :2]
        sig[r, : f.n_hits] = f.hit_sigma_m
        cov[r, : f.n_hits] = f.hit_covariances()
    return xy, sig, cov


@dataclass(frozen=True, eq=False)
class _Screen:
    """What :func:`_screen_pairs` finds for the (a, b) pairs of a sensor pair.

    ``cost``: :func:`pair_cost` of pairs that pass, else inf; ``clear``: passed every
    check by more than :data:`_SCREEN_TOL`; ``p_enu`` (.., 3), ``range_a``, ``range_b``
    (m), ``sin_angle``: the closest approach; ``hits_a``/``hits_b``: padded hit positions
    and covariances of each side's fixes.
    """

    cost: np.ndarray
    clear: np.ndarray
    p_enu: np.ndarray
    miss: np.ndarray
    range_a: np.ndarray
    range_b: np.ndarray
    sin_angle: np.ndarray
    hits_a: tuple[np.ndarray, np.ndarray]
    hits_b: tuple[np.ndarray, np.ndarray]


def _screen_pairs(
    fa: Sequence[Fix],
    fb: Sequence[Fix],
    config: TrackerConfig,
    pre: tuple[_Arrays, _Arrays] | None = None,
) -> _Screen:
    """The triangulation checks of every (a, b) pair, vectorised (see :class:`_Screen`).

    Arrays are ``(len(fa), len(fb))``. The checks of :func:`_triangulate`; a pair within
    :data:`_SCREEN_TOL` of any threshold is decided by :func:`_triangulate` itself.
    ``pre``: :func:`_fix_arrays` of ``fa`` and of ``fb``, when the caller has them.
    """
    arrays_a, arrays_b = (_fix_arrays(fa), _fix_arrays(fb)) if pre is None else pre
    oa, da, ta, ca, hxa, sga, cva = arrays_a
    ob, db, tb, cb, hxb, sgb, cvb = arrays_b
    min_sin = math.sin(math.radians(config.fusion_min_angle_deg))
    same, worst, d2, p, miss, s, t, sin_angle = screen_pairs_kernel(
        oa, da, ta, ca, hxa, sga, cva, ob, db, tb, cb, hxb, sgb, cvb,
        float(config.step_window_s), min_sin, float(config.fusion_max_miss_m),
        float(config.fusion_hit_gate_sigma),
    )  # fmt: skip
    clear = same & (worst > _SCREEN_TOL)
    cost = np.where(clear, d2, np.inf)
    for r, c in zip(*np.nonzero(same & (np.abs(worst) <= _SCREEN_TOL)), strict=True):
        tri = _triangulate(fa[r], fb[c], config)
        if tri is not None:
            cost[r, c] = pair_cost(tri[0].hits_enu[0], fa[r], fb[c])
    return _Screen(cost, clear, p, miss, s, t, sin_angle, (hxa, cva), (hxb, cvb))


def _triangulate_screened(
    fa: Sequence[Fix],
    fb: Sequence[Fix],
    rows: np.ndarray,
    cols: np.ndarray,
    screen: _Screen,
    config: TrackerConfig,
) -> list[tuple[Fix, float]]:
    """:func:`_triangulate` of the pairs ``(fa[rows[k]], fb[cols[k]])``, all at once.

    For pairs that cleared the screen: the same formulas on the screen's arrays (equal
    to the scalar ones up to float round-off).
    """
    if len(rows) == 0:
        return []
    p = screen.p_enu[rows, cols]
    miss = screen.miss[rows, cols]
    ga = np.array([fa[i].direction_enu[:2] for i in rows.tolist()])
    gb = np.array([fb[j].direction_enu[:2] for j in cols.tolist()])
    (hxa, cva), (hxb, cvb) = screen.hits_a, screen.hits_b
    cov, sigma = triangulation_cov_kernel(
        p, miss, screen.sin_angle[rows, cols], screen.range_a[rows, cols],
        screen.range_b[rows, cols], ga, gb, hxa[rows], cva[rows], hxb[cols], cvb[cols],
        float(config.ray_sigma_rad),
    )  # fmt: skip
    # the fixes' hit, road point and sigma: rows of read-only copies made once
    p_ro, sigma_ro = p.copy(), sigma.copy()
    for arr in (p_ro, sigma_ro, cov):
        arr.setflags(write=False)
    out = []
    p_l, sigma_l, cov_l = p.tolist(), sigma.tolist(), cov.reshape(-1, 4).tolist()
    for k, (r, c) in enumerate(zip(rows.tolist(), cols.tolist(), strict=True)):
        a, b = fa[r], fb[c]
        scores = [v for v in (a.score, b.score) if v is not None]
        t_s = 0.5 * (a.t_s + b.t_s)
        if _plain(t_s, p_l[k], sigma_l[k], cov_l[k]):
            fix = _trusted_fused_fix(a, b, t_s, p_ro, sigma_ro, cov, k, scores)
            out.append((fix, float(miss[k])))
            continue
        road = p[k] if (a.road_hit_enu is not None or b.road_hit_enu is not None) else None
        fix = _fused_fix(
            t_s,
            "+".join(sorted((a.sensor, b.sensor))),
            a.cls,
            a.detection_index,
            a.origin_enu,
            a.direction_enu,
            p[k][None, :],
            np.array([sigma[k]]),
            road,
            max(scores) if scores else None,
            cov[k][None],
        )
        out.append((fix, float(miss[k])))
    return out


def _plain(t_s: float, p: list[float], sigma: float, cov: list[float]) -> bool:
    """Whether :func:`_fused_fix` would trust these values (finite, sigma > 0, SPD cov).

    ``cov`` flattened ``[c00, c01, c10, c11]``. A sum is finite only if every term is;
    one that overflows says False, and the checking constructor then decides.
    """
    c00, c01, c10, c11 = cov
    return (
        math.isfinite(t_s + p[0] + p[1] + p[2] + sigma + c00 + c01 + c10 + c11)
        and sigma > 0
        and c01 == c10
        and c00 > 0
        and c00 * c11 - c01 * c10 > 0
    )


def _trusted_fused_fix(
    a: Fix,
    b: Fix,
    t_s: float,
    p: np.ndarray,
    sigma: np.ndarray,
    cov: np.ndarray,
    k: int,
    scores: list[float],
) -> Fix:
    """:func:`_fused_fix` of row ``k`` of a screened pair, its checks passed already.

    The same values it makes when they pass (a copy of the direction renormalised; the
    hit, road point, sigma and covariance: row ``k`` of the read-only ``p``, ``sigma``
    and ``cov``), without the per-fix checks.
    """
    unit = np.array(a.direction_enu, dtype=np.float64)
    unit /= math.sqrt(float(unit.dot(unit)))  # np.linalg.norm's own formula
    unit.setflags(write=False)
    hits = p[k : k + 1]
    road = p[k] if (a.road_hit_enu is not None or b.road_hit_enu is not None) else None
    sig = sigma[k : k + 1]
    cov_k = cov[k : k + 1]
    sensor = a.sensor + "+" + b.sensor if a.sensor <= b.sensor else b.sensor + "+" + a.sensor
    return Fix._trusted(
        t_s,
        sensor,
        a.cls,
        a.detection_index,
        a.origin_enu,
        unit,
        hits,
        sig,
        road,
        max(scores) if scores else None,
        cov_k,
    )
