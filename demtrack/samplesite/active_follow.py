"""The simulated heads' controller: follow one target, zoom on it, hand it over ahead of time.

A real follower knows only what its cameras measure and what its heads' encoders read,
so this one does too. Each frame, every vehicle box is geolocated (foot pixel ray cast
against the site DEM, with the **calibrated** mount yaw and the encoder's pose reading),
moved to the object's centre (the foot offset of
:func:`~demtrack.core.geolocation.fix_builder.default_foot_offsets`) and, when it falls in
the gate, fed to a constant-velocity Kalman filter of the target's ground position.
Commands for the next frame come from that estimate:

- the **owner** (the head assigned to the target) aims at the position predicted one
  frame ahead and zooms so the car spans a band of the image width (:class:`FollowParams`);
- every half second the hand-off is planned: along the path predicted on the roads, the
  first instant the owner loses its line of sight (terrain, crowns, roofs, range), and the
  head that has a clear line soonest from then on (the line of sight, not the current
  field of view: any head can turn). That **standby** head is slewed to the acquisition
  point once its slew time (:func:`~demtrack.core.camera.head_motion.time_to_reach`) plus
  a margin reaches the time left, then follows the estimate;
- the standby takes the target over when it measures it and the owner has lost it (or
  is about to), and the old owner goes home; every other head rests at its stored pan,
  tilt and widest field of view (so the heads cover at least what fixed cameras would).

The predictor of :mod:`demtrack.core.visibility.handoff` is not called as it stands: it
holds the current camera's pose fixed, so for a head that turns with the target it would
predict an exit from its field of view every few seconds.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from demtrack.core.camera.head_motion import HeadCommand, HeadState, SlewLimits, time_to_reach
from demtrack.core.camera.pantilt import PanTiltHead
from demtrack.core.camera.pinhole import Camera
from demtrack.core.camera.pointing import point_head_at
from demtrack.core.camera.pose_series import PoseSample, camera_at
from demtrack.core.camera.zoom_control import ZoomBand, zoom_to_band
from demtrack.core.camera.zoom_lens import ZoomTable, intrinsics_for_hfov
from demtrack.core.geolocation.fix_builder import default_foot_offsets
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.terrain.dem import Dem
from demtrack.core.tracking.roadfollow import follow_road
from demtrack.core.tracking.types import Detection
from demtrack.core.visibility.viewshed import target_visible_fraction

__all__ = ["FollowParams", "Follower", "HeadInfo", "ZoomedHead"]


@dataclass(frozen=True)
class FollowParams:
    """The controller's settings.

    Parameters
    ----------
    size_band : tuple of 2 float
        The owner zooms when the car's box width leaves this share of the image width.
    size_goal : float
        ...and then aims for this share.
    min_hfov_deg : float
        Narrowest field of view the controller asks for (degrees), above the lens's own.
    plan_every_s : float
        Hand-off planning interval (s).
    horizon_s, plan_dt_s : float
        The planned path's length and step (s).
    preslew_margin_s : float
        The standby starts turning this long before its slew time would be too late.
    max_range_m : float
        Farther than this, a head does not count as seeing the target.
    gate_m : float
        Measurements farther than this from the prediction are ignored (m).
    lost_s : float
        With no measurement for this long the estimate is dropped and the heads go home.
    """

    size_band: tuple[float, float] = (0.05, 0.14)
    size_goal: float = 0.08
    min_hfov_deg: float = 14.0
    plan_every_s: float = 0.5
    horizon_s: float = 10.0
    plan_dt_s: float = 0.5
    preslew_margin_s: float = 2.0
    max_range_m: float = 300.0
    gate_m: float = 8.0
    lost_s: float = 8.0


class ZoomedHead:
    """A head's cameras at poses, with the lens of each zoom worked out once.

    A head holds its zoom most of the time, and building the lens of a field of view
    (its distortion inverse is checked) costs far more than posing it.
    """

    def __init__(self, head: PanTiltHead, zoom: ZoomTable | None = None) -> None:
        self.head = head
        self.zoom = zoom
        self._heads: dict[float, PanTiltHead] = {}

    def camera(self, pose: PoseSample) -> Camera:
        """:func:`~demtrack.core.camera.pose_series.camera_at` of the head at ``pose``."""
        if pose.hfov_deg is None:
            return camera_at(self.head, pose)
        head = self._heads.get(pose.hfov_deg)
        if head is None:
            intr = intrinsics_for_hfov(self.head.intrinsics, pose.hfov_deg, self.zoom)
            head = self._heads[pose.hfov_deg] = replace(self.head, intrinsics=intr)
        return camera_at(head, replace(pose, hfov_deg=None))


@dataclass(frozen=True, eq=False)
class HeadInfo:
    """What the controller knows of one head: the calibrated mount, its limits, its rest."""

    head: PanTiltHead
    limits: SlewLimits
    home_pan_deg: float
    home_tilt_deg: float
    home_hfov_deg: float
    zoom: ZoomTable | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "_zoomed", ZoomedHead(self.head, self.zoom))

    def camera(self, reading: PoseSample) -> Camera:
        """The camera the controller believes in at an encoder reading."""
        return self._zoomed.camera(reading)  # type: ignore[attr-defined]


@dataclass
class _Plan:
    """The current hand-off plan (times on the scenario clock, s)."""

    next_sensor: str | None = None
    exit_t_s: float | None = None
    acquire_t_s: float | None = None
    acquire_enu: np.ndarray | None = None
    started: bool = False


@dataclass
class Follower:
    """Follows one vehicle with a set of heads (see the module docstring).

    Parameters
    ----------
    heads : mapping of str to HeadInfo
    dem : Dem
        The site DEM (geolocation and lines of sight).
    roads : sequence of shapely.LineString
        Road centre lines, for the predicted path.
    params : FollowParams
    dt_s : float
        The frame interval (s).
    """

    heads: Mapping[str, HeadInfo]
    dem: Dem
    roads: Sequence
    params: FollowParams
    dt_s: float
    owner: str | None = None
    handoffs: list[tuple[float, str, str]] = field(default_factory=list)
    _x: np.ndarray | None = None  # x, y, vx, vy (m, m/s)
    _cov: np.ndarray | None = None
    _z: float = 0.0
    _t: float = 0.0
    _last_fix_t: float = -math.inf
    _seen_t: dict[str, float] = field(default_factory=dict)
    _width: dict[str, float] = field(default_factory=dict)
    _pending: list[np.ndarray] = field(default_factory=list)
    _plan: _Plan = field(default_factory=_Plan)
    _next_plan_t: float = -math.inf

    def __post_init__(self) -> None:
        self._caster = RayCaster.for_dem(self.dem)
        self._offset_m = default_foot_offsets()["vehicle"]

    # ------------------------------------------------------------ measuring
    def _locate(
        self, dets: Sequence[Detection], readings: Mapping[str, PoseSample]
    ) -> list[tuple[str, np.ndarray, float]]:
        """Each vehicle box's ground centre estimate: ``(sensor, p_enu, width share)``."""
        rays = []
        for d in dets:
            if d.cls != "vehicle" or d.sensor not in readings:
                continue
            cam = self.heads[d.sensor].camera(readings[d.sensor])
            u0, _, u1, v1 = d.bbox
            o, r = cam.pixel_to_ray(0.5 * (u0 + u1), v1)
            rays.append((d.sensor, o[0], r[0], (u1 - u0) / cam.intrinsics.width))
        if not rays:
            return []
        hits = self._caster.cast(
            np.array([r[1] for r in rays]), np.array([r[2] for r in rays]), 2000.0, mode="first"
        )
        out = []
        for k, (sid, _, d, share) in enumerate(rays):
            if hits.counts[k] == 0:
                continue
            p = np.array(hits.points[hits.offsets[k]], dtype=np.float64)
            g = np.array([d[0], d[1]])
            if np.hypot(*g) > 1e-9:  # the foot is the near edge: move to the centre
                p[:2] += self._offset_m * g / np.hypot(*g)
            out.append((sid, p, share))
        return out

    def _predict_to(self, t_s: float) -> None:
        assert self._x is not None and self._cov is not None
        dt = t_s - self._t
        if dt <= 0:
            return
        f = np.eye(4)
        f[0, 2] = f[1, 3] = dt
        q = 3.0  # m^2/s^3: a car's accelerations
        g = np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]]) * q
        qm = np.zeros((4, 4))
        qm[np.ix_([0, 2], [0, 2])] = g
        qm[np.ix_([1, 3], [1, 3])] = g
        self._x = f @ self._x
        self._cov = f @ self._cov @ f.T + qm
        self._t = t_s

    def _update(self, p: np.ndarray, sigma_m: float) -> None:
        assert self._x is not None and self._cov is not None
        h = np.zeros((2, 4))
        h[0, 0] = h[1, 1] = 1.0
        s = h @ self._cov @ h.T + np.eye(2) * sigma_m**2
        k = self._cov @ h.T @ np.linalg.inv(s)
        self._x = self._x + k @ (p[:2] - self._x[:2])
        self._cov = (np.eye(4) - k @ h) @ self._cov
        self._z = float(p[2])

    def observe(
        self, t_s: float, dets: Sequence[Detection], readings: Mapping[str, PoseSample]
    ) -> None:
        """Take one frame's detections, with each head's encoder reading at the frame."""
        meas = self._locate(dets, readings)
        if self._x is None:
            self._start(t_s, meas)
            return
        self._predict_to(t_s)
        best: dict[str, tuple[float, np.ndarray, float]] = {}
        for sid, p, share in meas:
            d = float(np.hypot(*(p[:2] - self._x[:2])))
            if d < self.params.gate_m and (sid not in best or d < best[sid][0]):
                best[sid] = (d, p, share)
        for sid, (_, p, share) in sorted(best.items()):
            rng_m = float(np.linalg.norm(p - self.heads[sid].head.position_enu))
            self._update(p, 0.5 + 0.01 * rng_m)
            self._seen_t[sid] = t_s
            self._width[sid] = share
            self._last_fix_t = t_s
        if t_s - self._last_fix_t > self.params.lost_s:
            self._x = self._cov = None
            self.owner = None
            self._plan = _Plan()

    def _start(self, t_s: float, meas: list[tuple[str, np.ndarray, float]]) -> None:
        """Start on a box that continues one of the previous frame's (no lone false alarm)."""
        for sid, p, share in meas:
            for q in self._pending:
                if np.hypot(*(p[:2] - q[:2])) < 3.0:
                    v = (p[:2] - q[:2]) / self.dt_s
                    self._x = np.array([p[0], p[1], v[0], v[1]])
                    self._cov = np.diag([4.0, 4.0, 25.0, 25.0])
                    self._t, self._z, self._last_fix_t = t_s, float(p[2]), t_s
                    self._seen_t[sid], self._width[sid] = t_s, share
                    self.owner = sid
                    self._pending = []
                    return
        self._pending = [p for _, p, _ in meas]

    # ------------------------------------------------------------ predicting
    def predicted(self, ahead_s: np.ndarray) -> np.ndarray:
        """Predicted ground positions ``ahead_s`` seconds after the estimate (k, 3), m."""
        assert self._x is not None
        ahead = np.atleast_1d(np.asarray(ahead_s, dtype=np.float64))
        p, v = self._x[:2], self._x[2:]
        xy = follow_road(self.roads, p, v, ahead) if len(self.roads) else None
        if xy is None:
            xy = p[None, :] + ahead[:, None] * v[None, :]
        z = self.dem.sample(xy[:, 0], xy[:, 1])
        return np.column_stack([xy, np.nan_to_num(z, nan=self._z)])

    def _plan_handoff(self, t_s: float, cameras: Mapping[str, Camera]) -> None:
        """Who loses the target when along the predicted path, and who sees it next."""
        pr = self.params
        ahead = np.arange(0.0, pr.horizon_s + 1e-9, pr.plan_dt_s)
        path = self.predicted(ahead)
        seen = {
            sid: target_visible_fraction(
                self.dem, cam, path, 1.5, in_view=False, max_range_m=pr.max_range_m
            )
            >= 0.5
            for sid, cam in cameras.items()
        }
        owner = self.owner
        assert owner is not None
        lost = np.flatnonzero(~seen[owner])
        old = self._plan
        if not len(lost):
            self._plan = _Plan()
            return
        k_exit = int(lost[0])
        best: tuple[int, str] | None = None
        for sid, flags in seen.items():
            later = np.flatnonzero(flags[k_exit:]) if sid != owner else []
            if len(later) and (best is None or k_exit + int(later[0]) < best[0]):
                best = (k_exit + int(later[0]), sid)
        if best is None:
            self._plan = _Plan(exit_t_s=self._t + float(ahead[k_exit]))
            return
        k, sid = best
        started = old.started and old.next_sensor == sid
        self._plan = _Plan(
            sid, self._t + float(ahead[k_exit]), self._t + float(ahead[k]), path[k], started
        )

    # ------------------------------------------------------------ commanding
    def _zoom_for_range(self, info: HeadInfo, p_enu: np.ndarray, share: float) -> float:
        r = float(np.linalg.norm(p_enu - info.head.position_enu))
        angle = math.degrees(2 * math.atan2(2.25, max(r, 1.0)))
        return self._clip_hfov(info, angle / share)

    def _range(self, info: HeadInfo) -> tuple[float, float]:
        lo = max(info.limits.hfov_min_deg, self.params.min_hfov_deg)
        return lo, min(info.limits.hfov_max_deg, info.home_hfov_deg)

    def _clip_hfov(self, info: HeadInfo, hfov: float) -> float:
        lo, hi = self._range(info)
        return float(min(max(hfov, lo), hi))

    def _aim(self, info: HeadInfo, p_enu: np.ndarray) -> tuple[float, float]:
        # Centre the car's middle (half its 1.5 m height above the ground point). The
        # calibrated lens's centre ray: the zoom's keeps the principal point here.
        pan, tilt = point_head_at(info.head, np.asarray(p_enu) + [0.0, 0.0, 0.75])
        lim = info.limits
        return float(pan), float(min(max(tilt, lim.tilt_min_deg), lim.tilt_max_deg))

    def _home(self, info: HeadInfo) -> HeadCommand:
        return HeadCommand(info.home_pan_deg, info.home_tilt_deg, info.home_hfov_deg)

    def commands(
        self, t_s: float, states: Mapping[str, HeadState], readings: Mapping[str, PoseSample]
    ) -> dict[str, HeadCommand]:
        """Each head's command for the coming frame, from the estimate at ``t_s``."""
        out = {sid: self._home(info) for sid, info in self.heads.items()}
        if self._x is None or self.owner is None:
            return out
        pr = self.params
        if t_s >= self._next_plan_t:
            cams = {sid: self.heads[sid].camera(readings[sid]) for sid in self.heads}
            self._plan_handoff(t_s, cams)
            self._next_plan_t = t_s + pr.plan_every_s
        self._take_over(t_s)
        owner, plan = self.owner, self._plan
        info = self.heads[owner]
        lead = self.dt_s + (t_s - self._t)
        p_next = self.predicted(np.array([lead]))[0]
        pan, tilt = self._aim(info, p_next)
        hfov = states[owner].hfov_deg
        share = self._width.get(owner)
        lo, hi = pr.size_band
        if t_s - self._seen_t.get(owner, -math.inf) > 1.0:
            hfov = self._clip_hfov(info, hfov + 5.0)  # lost: widen to find it again
        else:  # the band rule, shared with the server's followers
            hfov = zoom_to_band(hfov, share, ZoomBand(lo, hi, pr.size_goal), self._range(info))
        out[owner] = HeadCommand(pan, tilt, hfov)
        nxt = plan.next_sensor
        if nxt is not None and nxt != owner and plan.acquire_enu is not None:
            ninfo = self.heads[nxt]
            hfov_n = self._zoom_for_range(ninfo, plan.acquire_enu, 0.5 * pr.size_goal)
            if (plan.acquire_t_s or t_s) - t_s > 1.0:
                npan, ntilt = self._aim(ninfo, plan.acquire_enu)
            else:  # about to appear: follow the estimate
                npan, ntilt = self._aim(ninfo, p_next)
            reach = time_to_reach(states[nxt], npan, ntilt, hfov_n, ninfo.limits)
            left = (plan.acquire_t_s or t_s) - t_s
            if plan.started or reach + pr.preslew_margin_s >= left:
                plan.started = True
                out[nxt] = HeadCommand(npan, ntilt, hfov_n)
        return out

    def _take_over(self, t_s: float) -> None:
        """Hand the target to the head that sees it when the owner has lost it."""
        owner = self.owner
        assert owner is not None
        dt = self.dt_s
        recent = [s for s, t in self._seen_t.items() if s != owner and t_s - t <= 1.5 * dt]
        if not recent:
            return
        plan = self._plan
        owner_lost = t_s - self._seen_t.get(owner, -math.inf) > 3.5 * dt
        leaving = plan.exit_t_s is not None and plan.exit_t_s - t_s <= 0.5
        if not (owner_lost or (leaving and plan.next_sensor in recent)):
            return
        new = plan.next_sensor if plan.next_sensor in recent else sorted(recent)[0]
        self.handoffs.append((t_s, owner, new))
        self.owner = new
        self._plan = _Plan()
        self._next_plan_t = -math.inf
