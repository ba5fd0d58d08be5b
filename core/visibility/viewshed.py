"""Viewsheds and coverage: which DEM cells a camera can see, and how many cameras see each.

A cell is visible from a camera when the straight line from the optical centre to a target
point ``target_height_m`` above the cell's centre meets no terrain on the way (the DEM
surface, with its trees and roofs, occludes), lies within the maximum range and, depending
on the mode, within the camera's current field of view (``"fov"``) or anywhere the pan-tilt
head can point (``"reachable"``: a pan interval and a tilt interval widened by half the
field of view). The sight lines are cast with :func:`~demtrack.core.raycast.cast.cast_rays`, so
"meets the terrain" means exactly what geolocation means by it. Earth curvature and
refraction optionally lower distant targets by ``d^2 (1 - k) / (2 R)``.

Two methods give the verdict:

``"exact"``
    One sight line per candidate cell, cast with the ray caster (the reference).
``"sweep"`` (default)
    A horizon sweep outwards from the observer (``core.visibility._viewshed_kernels``: XDraw-style,
    exact terrain samples on lines of cell centres, interpolated horizons) gives each cell
    a margin in metres and an estimate of how wrong the interpolation could make it; then
    exact sight lines re-check every cell whose margin is below ``SWEEP_RECHECK_M`` plus
    that estimate, whose sweep verdict differs from a neighbour's, or that the sweep could
    not judge, and, repeatedly, every unchecked neighbour of a cell whose verdict the
    re-check flipped. The answer is exact along every visibility boundary the sweep found;
    on the benchmark DEM it agrees with the exact method on 99.98 % of cells after
    re-checking about 11 % of them (``docs/benchmarks.md``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from ..camera.pinhole import Camera
from ..errors import CameraError
from ..raycast.cast import RayCaster, cast_rays
from ..terrain.dem import Dem
from . import _viewshed_kernels as _vk
from .target_heights import DEFAULT_TARGET_HEIGHT_M

__all__ = [
    "EARTH_RADIUS_M",
    "REFRACTION_K",
    "SWEEP_RECHECK_M",
    "SWEEP_SLACK_FACTOR",
    "BlindSpot",
    "PanTiltLimits",
    "blind_spot_labels",
    "blind_spots",
    "target_visible_fraction",
    "viewshed",
]

EARTH_RADIUS_M = 6_371_000.0
#: Standard coefficient of atmospheric refraction.
REFRACTION_K = 0.13
#: A sight line may touch the terrain this close to its target (fraction of the distance
#: plus an absolute part, m): the target stands on that very surface.
_TARGET_TOL_REL, _TARGET_TOL_M = 1e-3, 0.05
#: Sweep margins (m at the target) below this are re-checked with exact sight lines.
SWEEP_RECHECK_M = 0.5
#: ... plus this multiple of the sweep's own estimate of its horizon error there (m).
SWEEP_SLACK_FACTOR = 1.0
#: Sight lines cast per batch (progress is reported between batches).
_BATCH = 262_144


@dataclass(frozen=True)
class PanTiltLimits:
    """Where a head can point: pan interval (clockwise from its mount yaw) and tilt interval.

    ``pan_min_deg = -180, pan_max_deg = 180`` is a full circle.
    """

    pan_min_deg: float = -180.0
    pan_max_deg: float = 180.0
    tilt_min_deg: float = -90.0
    tilt_max_deg: float = 30.0


@dataclass(frozen=True)
class BlindSpot:
    """A connected area no camera sees: size and where it is (site frame, m).

    ``label`` is the area's value in :func:`blind_spot_labels` of the same coverage (its
    cells are ``labels == label``); 0 when unknown.
    """

    area_m2: float
    centroid_e_m: float
    centroid_n_m: float
    bbox: tuple[float, float, float, float]
    label: int = 0


def _half_fov_deg(camera: Camera) -> tuple[float, float]:
    intr = camera.intrinsics
    hx = np.degrees(np.arctan((intr.width / 2) / intr.fx))
    hy = np.degrees(np.arctan((intr.height / 2) / intr.fy))
    return float(hx), float(hy)


def _reachable(
    camera: Camera, mount_yaw_deg: float, limits: PanTiltLimits, d: np.ndarray
) -> np.ndarray:
    """Sight directions ``d`` (n, 3) within the head's pan/tilt range widened by the FOV."""
    half_x, half_y = _half_fov_deg(camera)
    az = np.degrees(np.arctan2(d[:, 0], d[:, 1]))
    el = np.degrees(np.arctan2(d[:, 2], np.hypot(d[:, 0], d[:, 1])))
    ok = (el >= limits.tilt_min_deg - half_y) & (el <= limits.tilt_max_deg + half_y)
    span = limits.pan_max_deg - limits.pan_min_deg
    if span + 2 * half_x < 360.0:
        rel = (az - mount_yaw_deg - limits.pan_min_deg + half_x) % 360.0
        ok &= rel <= span + 2 * half_x
    return ok


def viewshed(
    dem: Dem,
    camera: Camera,
    *,
    mode: str = "fov",
    target_height_m: float = DEFAULT_TARGET_HEIGHT_M,
    max_range_m: float = 1000.0,
    mount_yaw_deg: float = 0.0,
    limits: PanTiltLimits | None = None,
    curvature: bool = False,
    method: str = "sweep",
    progress: Callable[[float], None] | None = None,
) -> np.ndarray:
    """Boolean raster on ``dem.grid``: True where the camera sees the target point.

    Parameters
    ----------
    dem : Dem
    camera : Camera
        Position (and, for ``mode="fov"``, pointing and intrinsics).
    mode : {"fov", "reachable"}
        Current field of view, or anywhere within the pan-tilt ``limits``.
    target_height_m : float
        Height of the target point above the surface (m): 0 for the ground itself; the
        default is a standing person's head (1.7 m), a car's roof is 1.5 m
        (:mod:`~demtrack.core.visibility.target_heights`).
    max_range_m : float
        Cells farther than this (3-D distance) are not seen.
    mount_yaw_deg : float
        Azimuth at pan 0 (``mode="reachable"`` only).
    limits : PanTiltLimits, optional
        Pan/tilt range (``mode="reachable"``); full circle by default.
    curvature : bool
        Lower targets by earth curvature less standard refraction.
    method : {"sweep", "exact"}
        Horizon sweep with exact re-checks near every boundary (fast), or one exact sight
        line per cell. ``"sweep"`` falls back to ``"exact"`` when the camera is not above
        the surface inside the DEM.
    progress : callable, optional
        Called with the share done (0 to 1, non-decreasing; last call 1.0).

    Returns
    -------
    ndarray, bool, shape ``dem.grid.shape``
        False also where the DEM has no data.
    """
    if mode not in ("fov", "reachable"):
        raise CameraError(f"unknown viewshed mode {mode!r}; choose 'fov' or 'reachable'")
    if method not in ("sweep", "exact"):
        raise CameraError(f"unknown viewshed method {method!r}; choose 'sweep' or 'exact'")
    if not (np.isfinite(max_range_m) and max_range_m > 0):
        raise CameraError(f"max_range_m must be positive, got {max_range_m!r}")
    report = progress or (lambda share: None)
    g = dem.grid
    c = np.asarray(camera.position_enu, dtype=np.float64)
    th = float(target_height_m)
    curv = (1.0 - REFRACTION_K) / (2.0 * EARTH_RADIUS_M) if curvature else 0.0
    cand: np.ndarray = np.empty(g.shape, bool)
    _vk.candidates_kernel(
        dem.elevation, float(g.x_min), float(g.y_max), float(g.cell_m), c[0], c[1], c[2],
        th, curv, float(max_range_m), cand,
    )  # fmt: skip
    cand = cand.reshape(-1)
    if mode == "fov":
        idx = np.flatnonzero(cand)
        cand[idx[~camera.in_view(_targets(dem, idx, c, th, curv))]] = False
    elif not _reaches_everywhere(camera, limits or PanTiltLimits()):
        idx = np.flatnonzero(cand)
        d = _targets(dem, idx, c, th, curv) - c
        cand[idx[~_reachable(camera, mount_yaw_deg, limits or PanTiltLimits(), d)]] = False
    if method == "sweep" and _sweepable(dem, c):
        seen = _sweep(dem, c, cand.reshape(g.shape), th, curv, report)
    else:
        idx = np.flatnonzero(cand)
        seen = np.zeros(g.nrows * g.ncols, bool)
        if len(idx):
            d = _targets(dem, idx, c, th, curv) - c
            seen[idx] = _clear_sight_idx(dem, c, d, np.linalg.norm(d, axis=1), report)
    report(1.0)
    return seen.reshape(g.shape)


def _targets(dem: Dem, idx: np.ndarray, c: np.ndarray, th: float, curv: float) -> np.ndarray:
    """Target points (n, 3) above the centres of the flat cells ``idx``, site frame (m)."""
    g = dem.grid
    r, q = np.divmod(idx, g.ncols)
    x, y = g.from_grid(q, r)
    z = dem.elevation.reshape(-1)[idx].astype(np.float64) + th
    z -= np.hypot(x - c[0], y - c[1]) ** 2 * curv
    return np.column_stack([x, y, z])


def _reaches_everywhere(camera: Camera, limits: PanTiltLimits) -> bool:
    """The head (widened by the field of view) covers every direction."""
    half_x, half_y = _half_fov_deg(camera)
    full_pan = limits.pan_max_deg - limits.pan_min_deg + 2 * half_x >= 360.0
    return bool(
        full_pan and limits.tilt_min_deg - half_y <= -90.0 and limits.tilt_max_deg + half_y >= 90.0
    )


def _sweepable(dem: Dem, c: np.ndarray) -> bool:
    """The sweep needs the camera inside the surface's domain and above it."""
    x0, y0, x1, y1 = dem.grid.centre_bounds
    if not (x0 <= c[0] <= x1 and y0 <= c[1] <= y1) or min(dem.grid.shape) < 2:
        return False
    ground = float(dem.sample(c[:1], c[1:2])[0])
    return bool(np.isfinite(ground) and c[2] > ground)


def _sweep(
    dem: Dem,
    c: np.ndarray,
    cand: np.ndarray,
    th: float,
    curv: float,
    report: Callable[[float], None],
) -> np.ndarray:
    """Sweep margins, then exact sight lines wherever the sweep's verdict may be wrong."""
    g = dem.grid
    gx, gy = g.to_grid(c[:1], c[1:2])
    margin = np.empty(g.shape, np.float32)
    slack = np.empty(g.shape, np.float32)
    _vk.sweep_margin_kernel(
        dem.elevation, float(gx[0]), float(gy[0]), float(c[2]), float(g.cell_m), th, curv,
        margin, slack,
    )  # fmt: skip
    report(0.1)
    with np.errstate(invalid="ignore"):
        seen = cand & (margin > 0)
        unsure = ~(np.abs(margin) >= SWEEP_RECHECK_M + SWEEP_SLACK_FACTOR * slack)  # and NaN
    edge = np.empty(g.shape, bool)
    _vk.boundary_kernel(seen, cand, edge)
    checked = cand & (unsure | edge)
    idx = np.flatnonzero(checked)
    dem_arrays = RayCaster.for_dem(dem).kernel_dem
    for k in range(0, len(idx), _BATCH):
        _vk.refine_kernel(
            *dem_arrays, c[0], c[1], c[2], th, curv, _TARGET_TOL_REL, _TARGET_TOL_M, cand,
            seen, checked, idx[k : k + _BATCH],
        )  # fmt: skip
        report(min(0.1 + 0.9 * min(k + _BATCH, len(idx)) / len(idx), 1.0))
    return seen


def _clear_sight_idx(
    dem: Dem,
    c: np.ndarray,
    d: np.ndarray,
    dist: np.ndarray,
    report: Callable[[float], None],
) -> np.ndarray:
    """For the sight lines ``c -> c + d`` (n, 3), True where no terrain is crossed."""
    out = np.zeros(len(d), bool)
    for k in range(0, len(d), _BATCH):
        sl = slice(k, k + _BATCH)
        reach = dist[sl] * (1.0 - _TARGET_TOL_REL) - _TARGET_TOL_M
        hits = cast_rays(
            dem, np.broadcast_to(c, (len(reach), 3)), d[sl], np.maximum(reach, 0.0), mode="first"
        )
        out[sl] = hits.counts == 0
        report(min(k + _BATCH, len(d)) / len(d))
    return out


def _clear_sight(
    dem: Dem, c: np.ndarray, d: np.ndarray, dist: np.ndarray, cand: np.ndarray
) -> np.ndarray:
    """For the candidate sight lines ``c -> c + d``, True where no terrain is crossed."""
    idx = np.flatnonzero(cand)
    seen = np.zeros(len(d), bool)
    if len(idx):
        seen[idx] = _clear_sight_idx(dem, c, d[idx], dist[idx], lambda share: None)
    return seen


def blind_spot_labels(coverage_count: np.ndarray, dem: Dem) -> np.ndarray:
    """The unseen areas with data, labelled 1, 2, ... by 8-connected component (0 elsewhere).

    Returns
    -------
    ndarray, int32, shape ``dem.grid.shape``
    """
    blind = (np.asarray(coverage_count) == 0) & ~dem.nodata
    labels, _ = ndimage.label(blind, structure=np.ones((3, 3), bool), output=np.int32)
    return labels


def blind_spots(
    coverage_count: np.ndarray, dem: Dem, *, min_area_m2: float = 0.0
) -> list[BlindSpot]:
    """Connected areas (8-neighbour) with zero coverage and data, largest first."""
    labels = blind_spot_labels(coverage_count, dem)
    n = int(labels.max(initial=0))
    if n == 0:
        return []
    blind = labels > 0
    cell_area = dem.grid.cell_m**2
    index = np.arange(1, n + 1)
    sizes = ndimage.sum(blind, labels, index) * cell_area
    centres = ndimage.center_of_mass(blind, labels, index)
    boxes = ndimage.find_objects(labels)
    out = []
    for k in np.argsort(-sizes):
        if sizes[k] < min_area_m2:
            break
        gy, gx = centres[k]
        e, n_ = dem.grid.from_grid(np.array(gx), np.array(gy))
        rs, cs = boxes[k]
        x0, y1 = dem.grid.from_grid(np.array(cs.start - 0.5), np.array(rs.start - 0.5))
        x1, y0 = dem.grid.from_grid(np.array(cs.stop - 0.5), np.array(rs.stop - 0.5))
        box = (float(x0), float(y0), float(x1), float(y1))
        out.append(BlindSpot(float(sizes[k]), float(e), float(n_), box, int(k) + 1))
    return out


def target_visible_fraction(
    dem: Dem,
    camera: Camera,
    points_enu: np.ndarray,
    height_m: float,
    *,
    samples: int = 8,
    max_range_m: float = 1000.0,
    in_view: bool = True,
) -> np.ndarray:
    """How much of a standing target the camera sees, per ground point.

    The target is the vertical segment from ``points_enu`` (on the ground) up to
    ``height_m``; ``samples`` points on it (from 5 % to 100 % of the height) are tested for a
    clear sight line and, with ``in_view``, for lying in the image.

    Parameters
    ----------
    points_enu : ndarray, shape (n, 3)
        Foot of each target, site frame (m).
    height_m : float
        Target height (about 1.7 m for a person, 1.5 m for a car).

    Returns
    -------
    ndarray, shape (n,)
        Share of the sample points seen: 1 fully visible, 0 hidden or out of view.
    """
    feet = np.atleast_2d(np.asarray(points_enu, dtype=np.float64))
    levels = np.linspace(0.05, 1.0, samples) * float(height_m)
    pts = np.repeat(feet, samples, axis=0)
    pts[:, 2] += np.tile(levels, len(feet))
    c = np.asarray(camera.position_enu, dtype=np.float64)
    d = pts - c
    dist = np.linalg.norm(d, axis=1)
    ok = (dist > 0) & (dist <= max_range_m)
    if in_view:
        ok &= camera.in_view(pts)
    return _clear_sight(dem, c, d, dist, ok).reshape(len(feet), samples).mean(axis=1)
