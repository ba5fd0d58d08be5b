"""True target motion for the sample-site scenarios: routes, speed profiles, poses.

A :class:`Route` is a dense polyline in the site frame (x east, y north, m) with stops.
:func:`drive` turns it into a :class:`Motion`: arc length against time under a cruise
speed, a lateral-acceleration limit on curves and a longitudinal acceleration limit, with
the object standing still for a dwell at each stop. Nothing here knows about cameras.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

__all__ = ["Motion", "Route", "drive", "offset_lane", "resample_polyline", "smooth_polyline"]


def resample_polyline(xy: np.ndarray, step_m: float = 0.5) -> np.ndarray:
    """Return ``xy`` (n, 2) resampled every ``step_m`` along its length (ends kept)."""
    xy = np.asarray(xy, dtype=np.float64)
    seg = np.hypot(*np.diff(xy, axis=0).T)
    keep = np.r_[True, seg > 1e-9]
    xy = xy[keep]
    d = np.r_[0.0, np.cumsum(np.hypot(*np.diff(xy, axis=0).T))]
    n = max(int(np.ceil(d[-1] / step_m)), 1)
    s = np.linspace(0.0, d[-1], n + 1)
    return np.column_stack([np.interp(s, d, xy[:, 0]), np.interp(s, d, xy[:, 1])])


def smooth_polyline(xy: np.ndarray, window_m: float, step_m: float = 0.5) -> np.ndarray:
    """Round a polyline's corners: resample every ``step_m`` and average over ``window_m``.

    The ends stay put (the average is taken over a window mirrored at each end), so a
    junction's right angle becomes a curve a vehicle can drive.
    """
    dense = resample_polyline(xy, step_m)
    half = max(int(round(window_m / step_m / 2)), 1)
    if len(dense) < 2 * half + 2:
        return dense
    # Point reflection at the ends keeps them fixed and straight.
    head = 2 * dense[0] - dense[half:0:-1]
    tail = 2 * dense[-1] - dense[-2 : -half - 2 : -1]
    padded = np.vstack([head, dense, tail])
    kernel = np.ones(2 * half + 1) / (2 * half + 1)
    out = np.column_stack([np.convolve(padded[:, j], kernel, mode="valid") for j in (0, 1)])
    return out


def offset_lane(xy: np.ndarray, offset_m: float) -> np.ndarray:
    """Shift a polyline (n, 2) sideways by ``offset_m`` (positive = to the right of travel)."""
    xy = np.asarray(xy, dtype=np.float64)
    tangent = np.gradient(xy, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    right = np.column_stack([tangent[:, 1], -tangent[:, 0]])
    return xy + offset_m * right


@dataclass(frozen=True)
class Route:
    """A path to follow and where to stop on it.

    Parameters
    ----------
    xy : ndarray, shape (n, 2)
        Dense polyline, site frame (m).
    stops : tuple of (float, float)
        ``(arc_length_m, dwell_s)``: come to rest at that arc length and stand still.
    """

    xy: np.ndarray
    stops: tuple[tuple[float, float], ...] = ()

    @property
    def s_m(self) -> np.ndarray:
        """Arc length at each vertex (m), shape (n,)."""
        return np.r_[0.0, np.cumsum(np.hypot(*np.diff(self.xy, axis=0).T))]


@dataclass(frozen=True, eq=False)
class Motion:
    """Where a target is when: arc length against time along a route.

    Parameters
    ----------
    route : Route
        The path.
    t_s : ndarray, shape (m,)
        Non-decreasing times (s), starting at the target's start time.
    s_m : ndarray, shape (m,)
        Arc length at those times (m).
    """

    route: Route
    t_s: np.ndarray
    s_m: np.ndarray

    @property
    def t_start(self) -> float:
        """First time (s)."""
        return float(self.t_s[0])

    @property
    def t_end(self) -> float:
        """Last time (s)."""
        return float(self.t_s[-1])

    def pose(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Position (m, (k, 2)) and heading (unit (k, 2)) at times ``t_s`` (clamped)."""
        t = np.clip(np.atleast_1d(np.asarray(t_s, dtype=np.float64)), self.t_start, self.t_end)
        s = np.interp(t, self.t_s, self.s_m)
        rs = self.route.s_m
        xy = self.route.xy
        p = np.column_stack([np.interp(s, rs, xy[:, 0]), np.interp(s, rs, xy[:, 1])])
        # The heading comes from a chord 1 m long around s, so it is defined while standing.
        a = np.clip(s - 0.5, 0.0, rs[-1])
        b = np.clip(s + 0.5, 0.0, rs[-1])
        pa = np.column_stack([np.interp(a, rs, xy[:, 0]), np.interp(a, rs, xy[:, 1])])
        pb = np.column_stack([np.interp(b, rs, xy[:, 0]), np.interp(b, rs, xy[:, 1])])
        h = pb - pa
        h /= np.maximum(np.linalg.norm(h, axis=1, keepdims=True), 1e-12)
        return p, h


def _curvature(xy: np.ndarray, window: int = 4) -> np.ndarray:
    """Unsigned curvature (1/m) of a densely sampled polyline, from chord turning angles."""
    n = len(xy)
    k = np.zeros(n)
    for i in range(n):
        a, b = max(i - window, 0), min(i + window, n - 1)
        if b - a < 2:
            continue
        m = (a + b) // 2
        v1, v2 = xy[m] - xy[a], xy[b] - xy[m]
        l1, l2 = np.linalg.norm(v1), np.linalg.norm(v2)
        if l1 < 1e-9 or l2 < 1e-9:
            continue
        turn = np.arccos(np.clip(v1 @ v2 / (l1 * l2), -1.0, 1.0))
        k[i] = turn / (0.5 * (l1 + l2))
    return k


def drive(
    route: Route,
    *,
    t0_s: float = 0.0,
    cruise_m_s: float = 8.0,
    lateral_acc_m_s2: float = 2.0,
    acc_m_s2: float = 1.5,
    start_speed_m_s: float | None = None,
    end_speed_m_s: float | None = None,
    speed_limits: Sequence[tuple[float, float, float]] = (),
) -> Motion:
    """Time a route: as fast as cruise, curves and acceleration allow, stopping at stops.

    Parameters
    ----------
    route : Route
        The path and its stops.
    t0_s : float
        Start time (s).
    cruise_m_s : float
        Speed on straight road (m/s).
    lateral_acc_m_s2 : float
        Largest lateral acceleration on curves (m/s^2): ``v <= sqrt(a / curvature)``.
    acc_m_s2 : float
        Largest longitudinal acceleration and deceleration (m/s^2).
    start_speed_m_s, end_speed_m_s : float or None
        Speed at the ends (default: cruise, as if driving on from off the site).
    speed_limits : sequence of (s0_m, s1_m, v_m_s)
        Lower speed limits on arc-length spans.
    """
    s = route.s_m
    v = np.minimum(cruise_m_s, np.sqrt(lateral_acc_m_s2 / np.maximum(_curvature(route.xy), 1e-9)))
    for s0, s1, lim in speed_limits:
        v[(s >= s0) & (s <= s1)] = np.minimum(v[(s >= s0) & (s <= s1)], lim)
    v[0] = min(v[0], cruise_m_s if start_speed_m_s is None else start_speed_m_s)
    v[-1] = min(v[-1], cruise_m_s if end_speed_m_s is None else end_speed_m_s)
    stop_idx = [int(np.argmin(np.abs(s - s_stop))) for s_stop, _ in route.stops]
    v[stop_idx] = 0.0
    ds = np.diff(s)
    for i in range(1, len(s)):  # accelerate no faster than acc
        v[i] = min(v[i], np.sqrt(v[i - 1] ** 2 + 2 * acc_m_s2 * ds[i - 1]))
    for i in range(len(s) - 2, -1, -1):  # and brake no harder
        v[i] = min(v[i], np.sqrt(v[i + 1] ** 2 + 2 * acc_m_s2 * ds[i]))
    dt = 2.0 * ds / np.maximum(v[:-1] + v[1:], 1e-6)
    t = np.r_[0.0, np.cumsum(dt)]
    times, arcs = [t0_s], [0.0]
    dwell = dict(zip(stop_idx, (d for _, d in route.stops), strict=True))
    shift = t0_s
    for i in range(1, len(s)):
        times.append(t[i] + shift)
        arcs.append(s[i])
        if i in dwell:
            shift += dwell[i]
            times.append(t[i] + shift)
            arcs.append(s[i])
    return Motion(route, np.array(times), np.array(arcs))
