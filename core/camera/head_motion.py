"""Kinematics of a pan-tilt-zoom head: rate and acceleration limits, time-optimal moves.

A head has three axes. **Pan** is endless (degrees clockwise, wrapped to (-180, 180]) and
**tilt** is bounded (degrees, positive up); both are limited in rate and share one
acceleration limit. **Zoom** is the horizontal field of view, ``hfov_deg``, bounded and
limited in rate only (a zoom lens's motor reaches its speed in a few milliseconds, far
below the 10 Hz that heads report at).

An absolute move drives each axis along its time-optimal profile under those limits
(bang-coast-bang, "trapezoidal"): accelerate at the limit, cruise at the rate limit if the
move is long enough, decelerate at the limit so as to stop exactly on the target -- no
overshoot, and from any starting velocity (a head already moving the wrong way first
brakes). Pan goes the short way round: to the copy of the target (modulo 360 degrees)
nearest the point where the head would stop if it braked now, which is the plain short
way for a head at rest and stays the same copy all along the move. Axes move
independently; a move takes as long as its slowest axis (:func:`time_to_reach`).

A velocity command ramps each axis to the commanded rate (clamped to the limit) at the
acceleration limit and holds it; on tilt and zoom it brakes in time to stop at the limit.

:func:`step` integrates the profile *exactly* (each segment has constant acceleration),
so a state stepped by ``dt`` ten times equals the state stepped once by ``10 dt`` up to
float rounding: the rest of a time-optimal profile, seen from any point on it, is the
same profile (the principle of optimality), and the profile is recomputed from each new
state. The end of a move is snapped onto the target, so a head that arrives stays.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass, fields
from typing import Any

from ..errors import CameraError

__all__ = [
    "HeadCommand",
    "HeadState",
    "SlewLimits",
    "step",
    "time_to_reach",
]

#: Positions (degrees) and rates (degrees per second) closer than this count as equal.
_EPS = 1e-9


def _wrap(angle_deg: float) -> float:
    """Wrap an angle to (-180, 180] degrees."""
    w = math.fmod(angle_deg + 180.0, 360.0)
    if w < 0.0:
        w += 360.0
    w -= 180.0
    return 180.0 if w == -180.0 else w


def _finite(name: str, value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise CameraError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(out):
        raise CameraError(f"{name} must be finite, got {out!r}")
    return out


@dataclass(frozen=True)
class SlewLimits:
    """Rate, acceleration and range limits of a pan-tilt-zoom head.

    Parameters
    ----------
    pan_rate_deg_s, tilt_rate_deg_s : float
        Largest pan and tilt speeds (degrees per second, > 0).
    accel_deg_s2 : float
        Largest pan and tilt acceleration (degrees per second squared, > 0).
    zoom_rate_deg_s : float
        Largest change of the horizontal field of view (degrees per second, > 0).
    tilt_min_deg, tilt_max_deg : float
        Tilt range (degrees, positive up), ``tilt_min_deg < tilt_max_deg``.
    hfov_min_deg, hfov_max_deg : float
        Horizontal field-of-view range (degrees), ``0 < hfov_min_deg <= hfov_max_deg < 180``.
    """

    pan_rate_deg_s: float = 60.0
    tilt_rate_deg_s: float = 40.0
    accel_deg_s2: float = 120.0
    zoom_rate_deg_s: float = 10.0
    tilt_min_deg: float = -90.0
    tilt_max_deg: float = 30.0
    hfov_min_deg: float = 3.0
    hfov_max_deg: float = 60.0

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _finite(f.name, getattr(self, f.name)))
        for name in ("pan_rate_deg_s", "tilt_rate_deg_s", "accel_deg_s2", "zoom_rate_deg_s"):
            if getattr(self, name) <= 0.0:
                raise CameraError(f"{name} must be positive, got {getattr(self, name)!r}")
        if not self.tilt_min_deg < self.tilt_max_deg:
            raise CameraError(
                f"tilt_min_deg ({self.tilt_min_deg:g}) must be below "
                f"tilt_max_deg ({self.tilt_max_deg:g})"
            )
        if not 0.0 < self.hfov_min_deg <= self.hfov_max_deg < 180.0:
            raise CameraError(
                "need 0 < hfov_min_deg <= hfov_max_deg < 180, got "
                f"{self.hfov_min_deg:g} and {self.hfov_max_deg:g}"
            )

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | None) -> SlewLimits:
        """Limits from a mapping of field names (``site.json``'s ``slew_limits``).

        ``None`` or a missing key gives the default; an unknown key is refused, naming it.
        """
        if d is None:
            return cls()
        if not isinstance(d, Mapping):
            raise CameraError(f"slew_limits must be a mapping, got {type(d).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(d) - known)
        if unknown:
            raise CameraError(
                f"slew_limits: unknown keys {unknown}; known keys are {sorted(known)}"
            )
        return cls(**dict(d))

    def to_dict(self) -> dict[str, float]:
        """Every field by name (the inverse of :meth:`from_dict`)."""
        return asdict(self)


@dataclass(frozen=True)
class HeadState:
    """Where a head points at a moment, and how fast it turns.

    Parameters
    ----------
    t_s : float
        UNIX time (seconds, UTC).
    pan_deg, tilt_deg : float
        Pan (degrees clockwise, in (-180, 180]) and tilt (degrees, positive up).
    hfov_deg : float
        Horizontal field of view (degrees).
    pan_rate_deg_s, tilt_rate_deg_s : float
        Pan and tilt rates (degrees per second).
    """

    t_s: float
    pan_deg: float
    tilt_deg: float
    hfov_deg: float
    pan_rate_deg_s: float = 0.0
    tilt_rate_deg_s: float = 0.0

    def __post_init__(self) -> None:
        for f in fields(self):
            object.__setattr__(self, f.name, _finite(f.name, getattr(self, f.name)))
        object.__setattr__(self, "pan_deg", _wrap(self.pan_deg))


@dataclass(frozen=True)
class HeadCommand:
    """A command to a head: either absolute targets or rates, never both.

    Parameters
    ----------
    pan_deg, tilt_deg, hfov_deg : float or None
        Absolute targets (degrees). An axis left ``None`` in an absolute command holds:
        it brakes to a stop where it can.
    pan_rate_deg_s, tilt_rate_deg_s, zoom_rate_deg_s : float or None
        Rates (degrees per second; zoom is the change of ``hfov_deg``). ``None`` is 0.
        Clamped to the limits when applied.
    """

    pan_deg: float | None = None
    tilt_deg: float | None = None
    hfov_deg: float | None = None
    pan_rate_deg_s: float | None = None
    tilt_rate_deg_s: float | None = None
    zoom_rate_deg_s: float | None = None

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if value is not None:
                object.__setattr__(self, f.name, _finite(f.name, value))
        if self.is_absolute and self.is_velocity:
            raise CameraError(
                "a head command is either absolute (pan_deg, tilt_deg, hfov_deg) "
                "or a velocity (pan_rate_deg_s, tilt_rate_deg_s, zoom_rate_deg_s), not both"
            )

    @property
    def is_absolute(self) -> bool:
        """True when any absolute target is given."""
        return any(v is not None for v in (self.pan_deg, self.tilt_deg, self.hfov_deg))

    @property
    def is_velocity(self) -> bool:
        """True when any rate is given."""
        rates = (self.pan_rate_deg_s, self.tilt_rate_deg_s, self.zoom_rate_deg_s)
        return any(v is not None for v in rates)


# One axis's profile: segments of (duration_s, acceleration_deg_s2) from a start state.
_Segments = list[tuple[float, float]]


def _brake(v0: float, accel: float) -> tuple[float, _Segments]:
    """Stopping displacement and the one braking segment from rate ``v0``."""
    if abs(v0) <= _EPS:
        return 0.0, []
    return v0 * abs(v0) / (2.0 * accel), [(abs(v0) / accel, -math.copysign(accel, v0))]


def _move_profile(d: float, v0: float, vmax: float, accel: float) -> _Segments:
    """Time-optimal segments from (0, ``v0``) to rest at displacement ``d``.

    Under ``|v| <= vmax`` (after an initial braking to ``vmax`` when ``|v0|`` is above it)
    and ``|a| <= accel``. Works in the direction ``sigma`` the head must go beyond its
    stopping point; ``u0`` is the start rate in that direction (negative: moving away).
    """
    d_stop, brake = _brake(v0, accel)
    if abs(d - d_stop) <= _EPS:
        return brake
    sigma = 1.0 if d > d_stop else -1.0
    dist, u0 = sigma * d, sigma * v0
    peak = math.sqrt(max(accel * dist + 0.5 * u0 * u0, 0.0))
    if peak <= vmax:
        return [((peak - u0) / accel, sigma * accel), (peak / accel, -sigma * accel)]
    t1 = abs(vmax - u0) / accel
    d1 = 0.5 * (u0 + vmax) * t1
    t3 = vmax / accel
    d3 = 0.5 * vmax * t3
    t2 = max(dist - d1 - d3, 0.0) / vmax
    a1 = sigma * accel if vmax >= u0 else -sigma * accel
    return [(t1, a1), (t2, 0.0), (t3, -sigma * accel)]


def _rate_profile(v_target: float, v0: float, accel: float) -> _Segments:
    """Ramp from ``v0`` to ``v_target`` at the acceleration limit, then hold it."""
    ramp = abs(v_target - v0) / accel
    return [(ramp, math.copysign(accel, v_target - v0)), (math.inf, 0.0)]


def _duration(segments: _Segments) -> float:
    return math.fsum(t for t, _ in segments)


def _evaluate(segments: _Segments, dt: float, v0: float) -> tuple[float, float]:
    """Displacement (degrees) and rate ``dt`` seconds along the segments from rate ``v0``."""
    x, v, left = 0.0, v0, dt
    for seg_t, a in segments:
        if left <= 0.0:
            break
        t = min(seg_t, left)
        if t > 0.0:
            x += v * t + 0.5 * a * t * t
            v += a * t
            left -= t
    return x, v


def _pan_displacement(state: HeadState, target_deg: float, accel: float) -> float:
    """Displacement to the copy of the target nearest the head's stopping point."""
    d_stop, _ = _brake(state.pan_rate_deg_s, accel)
    return _wrap(target_deg - state.pan_deg - d_stop) + d_stop


# An axis's plan: its segments and the position it stops at (``None``: it never stops).
_Plan = tuple[_Segments, float | None]


def _axis_plans(
    state: HeadState, command: HeadCommand | None, limits: SlewLimits
) -> tuple[_Plan, _Plan]:
    """Pan and tilt plans under a command."""
    a = limits.accel_deg_s2
    cmd = command if command is not None else HeadCommand()
    if cmd.is_velocity:
        pan_v = max(-limits.pan_rate_deg_s, min(limits.pan_rate_deg_s, cmd.pan_rate_deg_s or 0.0))
        pan: _Plan = (_rate_profile(pan_v, state.pan_rate_deg_s, a), None)
        tilt_v = cmd.tilt_rate_deg_s or 0.0
        if abs(tilt_v) > _EPS:
            bound = limits.tilt_max_deg if tilt_v > 0 else limits.tilt_min_deg
            vmax = min(abs(tilt_v), limits.tilt_rate_deg_s)
            d = bound - state.tilt_deg
            return pan, (_move_profile(d, state.tilt_rate_deg_s, vmax, a), bound)
        tilt_target = None
    else:
        tilt_target = cmd.tilt_deg
        if cmd.pan_deg is None:
            d_stop, segs = _brake(state.pan_rate_deg_s, a)
            pan = (segs, state.pan_deg + d_stop)
        else:
            d = _pan_displacement(state, cmd.pan_deg, a)
            pan = (_move_profile(d, state.pan_rate_deg_s, limits.pan_rate_deg_s, a), cmd.pan_deg)
    if tilt_target is None:
        d_stop, _ = _brake(state.tilt_rate_deg_s, a)
        tilt_target = state.tilt_deg + d_stop
    goal = max(limits.tilt_min_deg, min(limits.tilt_max_deg, tilt_target))
    d = goal - state.tilt_deg
    return pan, (_move_profile(d, state.tilt_rate_deg_s, limits.tilt_rate_deg_s, a), goal)


def _zoom_goal(
    state: HeadState, command: HeadCommand | None, limits: SlewLimits
) -> tuple[float, float]:
    """Target field of view and the rate (degrees per second, > 0) to approach it at."""
    if command is not None and command.is_velocity:
        rate = command.zoom_rate_deg_s or 0.0
        if abs(rate) <= _EPS:
            return state.hfov_deg, limits.zoom_rate_deg_s
        goal = limits.hfov_max_deg if rate > 0 else limits.hfov_min_deg
        return goal, min(abs(rate), limits.zoom_rate_deg_s)
    goal = state.hfov_deg if command is None or command.hfov_deg is None else command.hfov_deg
    return max(limits.hfov_min_deg, min(limits.hfov_max_deg, goal)), limits.zoom_rate_deg_s


def _advance(plan: _Plan, x0: float, v0: float, dt: float) -> tuple[float, float]:
    """Position and rate ``dt`` seconds along a plan; exactly its end once past it."""
    segments, end = plan
    if end is not None and dt >= _duration(segments) - _EPS:
        return end, 0.0
    dx, v = _evaluate(segments, dt, v0)
    return x0 + dx, v


def step(
    state: HeadState, command: HeadCommand | None, dt_s: float, limits: SlewLimits
) -> HeadState:
    """Advance a head by ``dt_s`` seconds under a command.

    Parameters
    ----------
    state : HeadState
        The head now.
    command : HeadCommand or None
        What the head was told; ``None`` brakes every axis to a stop.
    dt_s : float
        Seconds to advance (>= 0).
    limits : SlewLimits
        The head's limits.

    Returns
    -------
    HeadState
        The state at ``state.t_s + dt_s``: exact along the piecewise constant-acceleration
        profile, and exactly on target (rates 0) once a move has ended.
    """
    dt = _finite("dt_s", dt_s)
    if dt < 0.0:
        raise CameraError(f"dt_s must not be negative, got {dt!r}")
    pan_plan, tilt_plan = _axis_plans(state, command, limits)
    pan, pan_v = _advance(pan_plan, state.pan_deg, state.pan_rate_deg_s, dt)
    tilt, tilt_v = _advance(tilt_plan, state.tilt_deg, state.tilt_rate_deg_s, dt)
    goal, rate = _zoom_goal(state, command, limits)
    gap = goal - state.hfov_deg
    hfov = goal if abs(gap) <= rate * dt + _EPS else state.hfov_deg + math.copysign(rate * dt, gap)
    return HeadState(state.t_s + dt, pan, tilt, hfov, pan_v, tilt_v)


def time_to_reach(
    state: HeadState,
    pan_deg: float,
    tilt_deg: float,
    hfov_deg: float | None,
    limits: SlewLimits,
) -> float:
    """Seconds an absolute move to ``(pan_deg, tilt_deg[, hfov_deg])`` takes from ``state``.

    The slowest axis's time-optimal profile (pan the short way from where it would stop,
    tilt and field of view clamped to the limits); ``hfov_deg`` ``None`` leaves zoom out.
    """
    command = HeadCommand(pan_deg=pan_deg, tilt_deg=tilt_deg, hfov_deg=hfov_deg)
    pan_plan, tilt_plan = _axis_plans(state, command, limits)
    goal, rate = _zoom_goal(state, command, limits)
    zoom_t = abs(goal - state.hfov_deg) / rate if hfov_deg is not None else 0.0
    return max(_duration(pan_plan[0]), _duration(tilt_plan[0]), zoom_t)
