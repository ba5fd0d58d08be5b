"""Pointing a head: the pan and tilt that centre a ground point, and whether it is seen.

The inverse of :func:`~demtrack.core.camera.pose_series.camera_at` for a levelled head
(an operator's "look here" on the map, a hand-off's slew command):
:func:`point_head_at` gives the ``(pan_deg, tilt_deg)`` at which the point projects to
the image centre, the pixel ``((W - 1) / 2, (H - 1) / 2)``. When the lens's principal
point is that pixel (and always for the optical axis) it is the azimuth and elevation of
the vector from the optical centre, ``pan = az - mount_yaw``, exact; otherwise the
centre pixel's ray is off the axis and a fixed-point iteration on the two angles
converges to 1e-10 deg (a few steps: the offset is a fraction of the field of view).

:func:`aim_check` adds what the operator needs to know before the head moves: whether
the sight line from the optical centre to the point clears the terrain (one ray cast
with :func:`~demtrack.core.raycast.cast.cast_rays`; blocked at distance ``d`` when it
meets the ground first), and whether the pan and tilt are within the head's
``slew_limits`` (keys ``pan_min_deg``, ``pan_max_deg``, ``tilt_min_deg``,
``tilt_max_deg`` when given; a pan may be taken a turn either way to fit).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from ..errors import PoseError
from ..raycast.cast import cast_rays
from ..terrain.dem import Dem
from .pantilt import PanTiltHead, wrap_deg
from .pinhole import rotation_from_azimuth_tilt_roll
from .zoom_lens import ZoomTable, intrinsics_for_hfov

__all__ = ["AimCheck", "aim_check", "point_head_at"]

#: The sight line may end this far (m) short of the point without counting as blocked.
END_TOLERANCE_M = 0.05


def _direction_deg(v: np.ndarray) -> tuple[float, float]:
    """Azimuth (clockwise from north) and elevation of a vector, degrees."""
    az = math.degrees(math.atan2(v[0], v[1]))
    el = math.degrees(math.atan2(v[2], math.hypot(v[0], v[1])))
    return az, el


def point_head_at(
    head: PanTiltHead,
    p_enu: ArrayLike,
    *,
    hfov_deg: float | None = None,
    zoom: ZoomTable | None = None,
) -> tuple[float, float]:
    """The head's ``(pan_deg, tilt_deg)`` that put ``p_enu`` in the image centre.

    Parameters
    ----------
    head : PanTiltHead
        A levelled head (roll 0).
    p_enu : array_like, shape (3,)
        The point (site frame, m).
    hfov_deg : float, optional
        The zoom the head will have (the lens of :func:`intrinsics_for_hfov`); None:
        the calibrated lens.
    zoom : ZoomTable, optional
        The lens's calibration table.

    Returns
    -------
    pan_deg : float
        In (-180, 180].
    tilt_deg : float
        In [-90, 90].

    Raises
    ------
    PoseError
        For a point at the optical centre or not three finite numbers.
    """
    p = np.asarray(p_enu, dtype=np.float64).reshape(-1)
    if p.shape != (3,) or not np.isfinite(p).all():
        raise PoseError(f"p_enu must be 3 finite numbers, got {np.asarray(p_enu).tolist()}")
    v = p - head.position_enu
    if float(np.linalg.norm(v)) < 1e-9:
        raise PoseError("the point is at the head's optical centre: no direction")
    intr = (
        head.intrinsics
        if hfov_deg is None
        else intrinsics_for_hfov(head.intrinsics, hfov_deg, zoom)
    )
    az_v, el_v = _direction_deg(v)
    # The centre pixel's ray in the camera frame (on the axis when cx, cy is the centre).
    xn, yn = intr.undistort([0.5 * (intr.width - 1)], [0.5 * (intr.height - 1)])
    d_cam = np.array([float(xn[0]), float(yn[0]), 1.0])
    az, el = az_v, el_v
    if abs(d_cam[0]) > 0.0 or abs(d_cam[1]) > 0.0:
        for _ in range(50):
            w = rotation_from_azimuth_tilt_roll(az, el, 0.0) @ d_cam
            az_w, el_w = _direction_deg(w)
            d_az = float(wrap_deg(az_v - az_w))
            d_el = el_v - el_w
            az, el = az + d_az, min(90.0, max(-90.0, el + d_el))
            if abs(d_az) < 1e-10 and abs(d_el) < 1e-10:
                break
    return float(wrap_deg(az - head.mount_yaw_deg)), float(el)


@dataclass(frozen=True)
class AimCheck:
    """Whether a head can look at a point, and where it would point.

    Attributes
    ----------
    visible : bool
        The sight line clears the terrain and the angles are within the slew limits.
    pan_deg, tilt_deg : float
        The pointing (:func:`point_head_at`; pan a turn off (-180, 180] where the limits
        need it).
    target_enu : tuple of float
        The point looked at (site frame, m), after ``target_height_m``.
    distance_m : float
        From the optical centre to it.
    reason : str
        Empty when visible; otherwise one line: blocked by terrain at ``d`` m, beyond a
        tilt or pan limit, or off the DEM.
    blocked_at_m : float or None
        Range (m) of the first terrain crossing before the point, when blocked.
    """

    visible: bool
    pan_deg: float
    tilt_deg: float
    target_enu: tuple[float, float, float]
    distance_m: float
    reason: str = ""
    blocked_at_m: float | None = None


def aim_check(
    head: PanTiltHead,
    p_enu: ArrayLike,
    dem: Dem,
    *,
    slew_limits: Mapping[str, float] | None = None,
    hfov_deg: float | None = None,
    zoom: ZoomTable | None = None,
    target_height_m: float = 1.0,
) -> AimCheck:
    """Point the head at ``p_enu`` and check it can see it (module notes).

    Parameters
    ----------
    head : PanTiltHead
    p_enu : array_like, shape (2,) or (3,)
        The point (site frame, m); with two coordinates (a map click) its height is the
        DEM's there.
    dem : Dem
        The terrain for the sight line.
    slew_limits : mapping, optional
        ``pan_min_deg``, ``pan_max_deg``, ``tilt_min_deg``, ``tilt_max_deg`` (any subset).
    hfov_deg, zoom : optional
        The zoom, as :func:`point_head_at`.
    target_height_m : float
        The point looked at is this far above ``p_enu`` (m): the middle of what stands
        there (default 1 m, a vehicle or a person), so a point on the ground is visible
        when something standing on it would be.

    Raises
    ------
    PoseError
        For a malformed point or height.
    """
    p = np.asarray(p_enu, dtype=np.float64).reshape(-1)
    if p.shape not in ((2,), (3,)) or not np.isfinite(p).all():
        raise PoseError(f"p_enu must be 2 or 3 finite numbers, got {np.asarray(p_enu).tolist()}")
    if not math.isfinite(target_height_m):
        raise PoseError(f"target_height_m must be finite, got {target_height_m}")
    if p.shape == (2,):
        z = float(dem.sample(p[:1], p[1:])[0])
        if not math.isfinite(z):
            pan, tilt = point_head_at(head, [p[0], p[1], 0.0], hfov_deg=hfov_deg, zoom=zoom)
            target = (float(p[0]), float(p[1]), math.nan)
            return AimCheck(False, pan, tilt, target, math.nan, "the point is off the DEM")
        p = np.array([p[0], p[1], z])
    target_arr = p + np.array([0.0, 0.0, float(target_height_m)])
    target = (float(target_arr[0]), float(target_arr[1]), float(target_arr[2]))
    pan, tilt = point_head_at(head, target_arr, hfov_deg=hfov_deg, zoom=zoom)
    v = target_arr - head.position_enu
    dist = float(np.linalg.norm(v))
    limits = dict(slew_limits or {})
    pan, why = _within_limits(pan, tilt, limits)
    if why:
        return AimCheck(False, pan, tilt, target, dist, why)
    reach = max(dist - END_TOLERANCE_M, 0.0)
    hits = cast_rays(dem, head.position_enu[None], (v / dist)[None], reach, mode="first")
    if hits.counts[0] > 0:
        at = float(hits.range_m[hits.offsets[0]])
        return AimCheck(
            False, pan, tilt, target, dist,
            f"blocked by terrain {at:.1f} m from the head ({dist - at:.1f} m before the point)",
            at,
        )  # fmt: skip
    return AimCheck(True, pan, tilt, target, dist)


def _within_limits(pan: float, tilt: float, limits: Mapping[str, float]) -> tuple[float, str]:
    """The pan to use (a turn off where that fits) and the limit broken ("" if none)."""
    lo_t, hi_t = limits.get("tilt_min_deg", -90.0), limits.get("tilt_max_deg", 90.0)
    if tilt < lo_t:
        return pan, f"tilt {tilt:.2f} deg is below the head's tilt limit {lo_t:g} deg"
    if tilt > hi_t:
        return pan, f"tilt {tilt:.2f} deg is above the head's tilt limit {hi_t:g} deg"
    lo_p, hi_p = limits.get("pan_min_deg", -math.inf), limits.get("pan_max_deg", math.inf)
    for candidate in (pan, pan - 360.0, pan + 360.0):
        if lo_p <= candidate <= hi_p:
            return candidate, ""
    return pan, f"pan {pan:.2f} deg is outside the head's pan limits {lo_p:g} .. {hi_p:g} deg"
