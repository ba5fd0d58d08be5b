"""Scenarios seen by pan-tilt-zoom heads that follow the target and hand it over.

The site's cameras act as simulated PTZ heads (slew-rate, acceleration and zoom-rate
limits: the sensor's ``slew_limits``, else the defaults of
:class:`~demtrack.core.camera.head_motion.SlewLimits`), stepped with
:func:`~demtrack.core.camera.head_motion.step` at the frame rate (in ``substeps`` equal
steps per frame, so the true pose between frames is known finely) under the commands of
:class:`~.active_follow.Follower`, a controller that knows only the detections and its
encoders (it aims from the previous frame's measured boxes, geolocated; the commands act
from the next frame on: one frame of control delay).

Each frame is rendered from every head's **true** pose (true mount yaw, pan, tilt, and
the zoom's intrinsics from :func:`~demtrack.core.camera.zoom_lens.intrinsics_for_hfov`)
with :func:`~.scene_render.render_frame`, so targets leave and enter the views as the
fields of view move. Lines of sight do not depend on the pose (a head turns about its
optical centre), so they are cast once for all frames.

Telemetry: each head reports its pose at its own rate (``telemetry_hz``, not aligned with
the frames; the phase is drawn), the true pan and tilt at the sample's instant plus
Gaussian noise (``telemetry_noise_deg``), the field of view exact; each sample is stamped
``latency_s`` **late** on the frame clock (it describes the pose ``latency_s`` before its
stamp), the convention of
:meth:`~demtrack.core.camera.pose_series.PoseSeries.at`'s ``latency_s``. The series cover
the whole run and a second either side.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from demtrack.core.camera.head_motion import HeadCommand, HeadState, SlewLimits, step
from demtrack.core.camera.pantilt import wrap_deg
from demtrack.core.camera.pose_series import PoseSample, PoseSeries
from demtrack.core.errors import SiteError
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.site.folder import Sensor, Site
from demtrack.core.tracking.types import Detection

from .active_follow import Follower, FollowParams, HeadInfo, ZoomedHead
from .cameras import TELEMETRY_LATENCY_S
from .scene_render import (
    STAT_KEYS,
    Scenario,
    ScenarioParams,
    Target,
    frame_times,
    line_of_sight,
    render_frame,
    target_points,
    true_yaws,
    truth_path,
)
from .world import World

__all__ = ["ActiveParams", "HeadTrack", "active_site", "make_active_scenario", "telemetry"]


@dataclass(frozen=True)
class ActiveParams:
    """How the heads move and report.

    Parameters
    ----------
    telemetry_hz : tuple of float
        Telemetry rate of each head, in sensor-id order (cycled).
    telemetry_noise_deg : float
        1-sigma noise of reported pan and tilt (degrees).
    latency_s : float
        How late each telemetry stamp is on the frame clock (s).
    substeps : int
        Head-motion steps per frame.
    follow : FollowParams
        The controller's settings.
    """

    telemetry_hz: tuple[float, ...] = (12.5, 15.0, 20.0)
    telemetry_noise_deg: float = 0.05
    latency_s: float = TELEMETRY_LATENCY_S
    substeps: int = 4
    follow: FollowParams = field(default_factory=FollowParams)

    def __post_init__(self) -> None:
        ok = (
            len(self.telemetry_hz) > 0
            and all(math.isfinite(r) and r > 0 for r in self.telemetry_hz)
            and math.isfinite(self.telemetry_noise_deg)
            and self.telemetry_noise_deg >= 0
            and math.isfinite(self.latency_s)
            and self.substeps >= 1
        )
        if not ok:
            raise SiteError(f"active scenario parameters out of range: {self}")


@dataclass(frozen=True, eq=False)
class HeadTrack:
    """One head's true motion: its state at each sub-step, scenario clock.

    ``t_s``, ``pan_deg`` (unwrapped: continuous through +-180), ``tilt_deg``, ``hfov_deg``
    all have shape (n,).
    """

    t_s: np.ndarray
    pan_deg: np.ndarray
    tilt_deg: np.ndarray
    hfov_deg: np.ndarray

    @classmethod
    def from_states(cls, states: Sequence[HeadState]) -> HeadTrack:
        """From the stepped states, in time order."""
        pan = np.unwrap(np.radians([s.pan_deg for s in states]))
        return cls(
            np.array([s.t_s for s in states]),
            np.degrees(pan),
            np.array([s.tilt_deg for s in states]),
            np.array([s.hfov_deg for s in states]),
        )

    def at(self, t_s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pan (wrapped), tilt, hfov at ``t_s`` (held constant outside the record)."""
        t = np.asarray(t_s, dtype=np.float64)
        pan = wrap_deg(np.interp(t, self.t_s, self.pan_deg))
        return pan, np.interp(t, self.t_s, self.tilt_deg), np.interp(t, self.t_s, self.hfov_deg)


def _limits(sensor: Sensor) -> SlewLimits:
    """The sensor's slew limits (defaults where it has none), never wider than its lens."""
    limits = SlewLimits.from_dict(sensor.slew_limits)
    if sensor.slew_limits is None or "hfov_max_deg" not in sensor.slew_limits:
        intr = sensor.head.intrinsics
        lens = math.degrees(2 * math.atan2(intr.width / 2, intr.fx))
        limits = replace(limits, hfov_max_deg=min(lens, 179.0))
        limits = replace(limits, hfov_min_deg=min(limits.hfov_min_deg, limits.hfov_max_deg))
    return limits


def active_site(site: Site, latency_s: float = TELEMETRY_LATENCY_S) -> Site:
    """``site`` with every sensor an active head whose telemetry is ``latency_s`` late."""
    sensors = {
        sid: replace(s, active=True, pose_latency_s=float(latency_s))
        for sid, s in site.sensors.items()
    }
    return replace(site, sensors=sensors)


def telemetry(
    track: HeadTrack,
    rate_hz: float,
    t0_s: float,
    t1_s: float,
    noise_deg: float,
    latency_s: float,
    rng: np.random.Generator,
) -> PoseSeries:
    """A head's reported pose series over ``[t0_s, t1_s]`` (see the module docstring)."""
    phase = float(rng.uniform(0.0, 1.0 / rate_hz))
    tau = np.arange(t0_s + phase, t1_s, 1.0 / rate_hz)
    pan, tilt, hfov = track.at(tau)
    pan = wrap_deg(pan + rng.normal(0.0, noise_deg, len(tau)))
    tilt = tilt + rng.normal(0.0, noise_deg, len(tau))
    return PoseSeries.from_arrays(tau + latency_s, pan, tilt, hfov_deg=hfov)


def _sample(
    t_s: float, state: HeadState, rng: np.random.Generator | None = None, noise_deg: float = 0.0
) -> PoseSample:
    """The pose of ``state`` at ``t_s``; with ``rng``, pan and tilt read with noise."""
    dp, dt = rng.normal(0.0, noise_deg, 2) if rng is not None and noise_deg > 0 else (0.0, 0.0)
    return PoseSample(
        float(t_s),
        float(wrap_deg(state.pan_deg + dp)),
        float(state.tilt_deg + dt),
        hfov_deg=float(state.hfov_deg),
    )


def _advance(
    state: HeadState, command: HeadCommand, dt_s: float, n: int, limits: SlewLimits
) -> list[HeadState]:
    """``n`` steps of ``dt_s`` under one command; every intermediate state, the last last."""
    out = []
    for _ in range(n):
        t_next = state.t_s + dt_s
        state = step(state, command, dt_s, limits)
        if state.t_s != t_next:  # the clock is the simulation's
            state = replace(state, t_s=t_next)
        out.append(state)
    return out


def _lines_of_sight(
    caster: RayCaster,
    centres: Mapping[str, np.ndarray],
    targets: Sequence[Target],
    world: World,
    frames: np.ndarray,
) -> dict[tuple[str, int], np.ndarray]:
    """(sensor, target id) -> line of sight of each sample point at each frame (f, k)."""
    out = {}
    for tg in targets:
        on = (frames >= tg.motion.t_start) & (frames <= tg.motion.t_end)
        xy, heading = tg.motion.pose(frames[on])
        pts = target_points(xy, heading, tg.size_m, world)
        k = pts.shape[1]
        for sid, centre in centres.items():
            mask = np.zeros((len(frames), k), dtype=bool)
            mask[on] = line_of_sight(caster, centre, pts).reshape(-1, k)
            out[(sid, tg.target_id)] = mask
    return out


def make_active_scenario(
    site: Site,
    world: World,
    name: str,
    targets: Sequence[Target],
    params: ScenarioParams,
    active: ActiveParams | None = None,
) -> Scenario:
    """Detections, truth and pose telemetry of ``targets`` followed by the site's heads.

    The heads start at their stored pan and tilt, zoomed out (the lens's own field of
    view). The detections' random draws use ``params.seed`` as the fixed cameras' do; the
    telemetry and encoder noise come from their own streams of the same seed.
    """
    active = ActiveParams() if active is None else active
    yaws = true_yaws(site)
    caster = RayCaster.for_dem(site.dem)
    frames = frame_times(targets, params.rate_hz)
    dt = 1.0 / params.rate_hz
    sids = sorted(site.sensors)
    true_heads: dict[str, ZoomedHead] = {}
    infos: dict[str, HeadInfo] = {}
    states: dict[str, HeadState] = {}
    for sid in sids:
        s = site.sensors[sid]
        true_heads[sid] = ZoomedHead(
            s.head.with_mount_yaw(yaws[sid]) if sid in yaws else s.head, s.zoom
        )
        intr = s.head.intrinsics
        hfov = math.degrees(2 * math.atan2(intr.width / 2, intr.fx))
        infos[sid] = HeadInfo(s.head, _limits(s), s.pan_deg, s.tilt_deg, hfov, s.zoom)
        states[sid] = HeadState(float(frames[0]), s.pan_deg, s.tilt_deg, hfov)
    centres = {sid: h.head.position_enu for sid, h in true_heads.items()}
    clear = _lines_of_sight(caster, centres, targets, world, frames)
    follower = Follower(infos, site.dem, list(site.roads.lines), active.follow, dt)
    seeds = np.random.SeedSequence(params.seed).spawn(2)
    rng = np.random.default_rng(params.seed)
    enc_rng, tel_rng = (np.random.default_rng(s) for s in seeds)
    history: dict[str, list[HeadState]] = {sid: [states[sid]] for sid in sids}
    stats = dict.fromkeys(STAT_KEYS, 0)
    stats["frames"] = len(frames)
    detections: list[Detection] = []
    sub = dt / active.substeps
    for i, t in enumerate(frames):
        t = float(t)
        cams = {sid: true_heads[sid].camera(_sample(t, states[sid])) for sid in sids}
        at_i = {key: mask[i] for key, mask in clear.items()}
        dets, _ = render_frame(t, cams, targets, world, caster, params, rng, stats, at_i)
        detections += dets
        readings = {
            sid: _sample(t, states[sid], enc_rng, active.telemetry_noise_deg) for sid in sids
        }
        follower.observe(t, dets, readings)
        commands = follower.commands(t, states, readings)
        for sid in sids:
            steps = _advance(states[sid], commands[sid], sub, active.substeps, infos[sid].limits)
            history[sid] += steps
            states[sid] = steps[-1]
    poses = {}
    for k, sid in enumerate(sids):
        track = HeadTrack.from_states(history[sid])
        rate = active.telemetry_hz[k % len(active.telemetry_hz)]
        poses[sid] = telemetry(
            track,
            rate,
            float(frames[0]) - 1.0,
            float(frames[-1]) + 1.0,
            active.telemetry_noise_deg,
            active.latency_s,
            tel_rng,
        )
    stats["handoffs"] = len(follower.handoffs)
    truths = [truth_path(tg, world) for tg in targets]
    return Scenario(name, params, detections, truths, stats, poses)
