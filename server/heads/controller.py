"""The head controller: one unit per active sensor, polled and driven at about 10 Hz.

Each tick (its own thread, never the event loop) reads every head's status, hands the
poses to the pose feed (``state.poses.accept``), and drives the heads by their mode:

``idle``     nothing is sent.
``slew``     an operator's absolute pan / tilt / zoom, sent once.
``look``     hold a ground point: aimed once (the head does not move, the point neither).
``follow``   aim at a track's predicted position each tick: the pipeline's newest
             estimate, extrapolated by the lead (the reorder lag, one tick, and the
             measured status latency), centred on the target's middle; a head whose
             lens has a zoom table also zooms so the target spans a band of the image
             width (:func:`~demtrack.core.camera.zoom_control.zoom_to_band`, the
             target's width from its range), within the head's and the table's range.
``handoff``  pre-positioned for a track another head is about to lose: slewed ahead of
             time, it starts following when the target is predicted to enter.

Hand-off (:mod:`.handover`): about once a second each following head asks whether it
will lose its sight line to the target within the horizon, and if so the hand-off
predictor (:func:`demtrack.core.visibility.handoff.predict_handoff`, every sensor at its
current pose) names the next camera and where it should point; an idle active head so
named is sent there as soon as its slew time (:func:`~demtrack.core.camera.head_motion.
time_to_reach`) plus a margin covers the time to entry, and is assigned the track. The
head that had it lets go when its sight line is predicted lost.

Every operator command and assignment is a journal row (:mod:`.journal`); at start the
last row of each head is applied again, so a restart resumes what was running.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from demtrack.core.camera.head_motion import SlewLimits
from demtrack.core.camera.zoom_control import ZoomBand, image_share, zoom_to_band
from demtrack.core.camera.zoom_lens import ideal_focal_px, intrinsics_for_hfov
from demtrack.core.errors import DemtrackError, NotFoundError
from demtrack.core.site.folder import Sensor, Site

from .adapter import HeadAdapter, HeadAdapterError, HeadStatus
from .aim import aim_pan_tilt, check_ground_point, sensor_at, track_motion
from .handover import HandoverPlanner
from .journal import HeadJournal

__all__ = ["HeadController", "HeadNotActiveError", "HeadUnit", "PoseFeed", "not_driven"]

log = logging.getLogger("demtrack.server")

#: ``feed(sensor_id, statuses)``: where the polled poses go.
PoseFeed = Callable[[str, Sequence[HeadStatus]], None]

#: A follow command is re-sent only when the aim moved more than this (degrees).
DEADBAND_DEG = 0.02
#: Target height (m) a follow aims at the middle of.
TARGET_HEIGHT_M = 1.5
#: Target width (m) a follow's zoom keeps in the band: a car's length, as the scenarios'.
TARGET_WIDTH_M = 4.5
#: A zoom goal is re-sent only when it moved more than this (degrees).
ZOOM_DEADBAND_DEG = 0.05


class HeadNotActiveError(DemtrackError, ValueError):
    """A command for a head the server does not drive (a fixed mount, or a gateway's)."""


def not_driven(sensor: Sensor) -> str:
    """Why the server does not drive this sensor's head, in one line."""
    if getattr(sensor, "active", False):
        return (
            f"sensor {sensor.id}'s head is not driven by this server (no head_adapter in"
            " site.json: its poses come from its gateway; --heads sim simulates one)"
        )
    return f"sensor {sensor.id} is on a fixed mount, not an active pan-tilt-zoom head"


@dataclass(eq=False)
class HeadUnit:
    """One active sensor's head and what the controller is doing with it."""

    sensor_id: str
    adapter: HeadAdapter
    limits: SlewLimits
    kind: str = "sim"
    mode: str = "idle"
    target: dict[str, Any] = field(default_factory=dict)
    status: HeadStatus | None = None
    error: str | None = None
    latency_s: float = 0.0
    last_aim: tuple[float, float] | None = None
    zoom_goal_deg: float | None = None
    unfed: list[HeadStatus] = field(default_factory=list)

    def info(self) -> dict[str, Any]:
        """``{sensor_id, kind, mode, target, status, error, latency_s, limits}``."""
        return {
            "sensor_id": self.sensor_id,
            "kind": self.kind,
            "mode": self.mode,
            "target": dict(self.target),
            "status": None if self.status is None else self.status.to_dict(),
            "error": self.error,
            "latency_s": self.latency_s,
            "limits": self.limits.to_dict(),
        }


class HeadController:
    """Drives the active heads of a site (see the module docstring).

    Parameters
    ----------
    site : Site
        The site (sensors, DEM, roads).
    units : sequence of HeadUnit
        One per active sensor.
    pipeline : Pipeline, optional
        Where live tracks come from (``follow``); None: no follow.
    feed : PoseFeed, optional
        Where each polled status goes.
    journal : HeadJournal, optional
        Where commands and assignments are written (and restored from).
    period_s, lead_s : float
        Tick (s) and the fixed part of the follow lead (s; the server passes its reorder lag).
    clock : callable
        Wall-clock UNIX seconds (journal rows, latency).
    handoff_horizon_s : float
        How far ahead hand-offs are predicted (s).
    feed_every_s : float
        The polled poses go to the feed in batches this often (s): one durable pose
        batch per head every half second instead of one per poll. Detections wait for
        their poses in the pipeline, so batching delays them, never loses them.
    zoom_band : ZoomBand, optional
        The target's share of the image width a following head keeps (default 5-14 %,
        aiming at 8 %); None: followers hold their zoom.
    """

    def __init__(
        self,
        site: Site,
        units: Sequence[HeadUnit],
        pipeline: Any = None,
        feed: PoseFeed | None = None,
        journal: HeadJournal | None = None,
        *,
        period_s: float = 0.1,
        lead_s: float = 0.0,
        clock: Callable[[], float] = time.time,
        handoff_horizon_s: float = 20.0,
        feed_every_s: float = 0.5,
        zoom_band: ZoomBand | None = ZoomBand(),  # noqa: B008 - frozen, shared safely
    ) -> None:
        self.site = site
        self.units = {u.sensor_id: u for u in units}
        self.pipeline = pipeline
        self.feed = feed
        self.journal = journal or HeadJournal(None)
        self.period_s, self.lead_s, self.clock = float(period_s), float(lead_s), clock
        self.planner = HandoverPlanner(site, horizon_s=handoff_horizon_s)
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.n_ticks = 0
        self.feed_every_s = float(feed_every_s)
        self._fed_at = -np.inf
        self.zoom_band = zoom_band

    # ------------------------------------------------------------ lifecycle
    def start(self) -> HeadController:
        """Restore the journal's last state of each head, then tick in a daemon thread."""
        self.restore()
        self._thread = threading.Thread(target=self._run, name="demtrack-heads", daemon=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        """Stop ticking (the heads keep their last command); the last poses are fed."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=10.0)
        with self._lock:
            self.flush_poses()

    def _run(self) -> None:
        while not self._stop.wait(self.period_s):
            try:
                self.tick()
            except Exception:  # noqa: BLE001 - one bad tick must not end head control
                log.exception("head controller tick failed")

    # ------------------------------------------------------------------ API
    def unit(self, sensor_id: str) -> HeadUnit:
        """The unit of an active sensor: 404 unknown, :class:`HeadNotActiveError` fixed."""
        sensor = self.site.sensor(sensor_id)  # UnknownSensorError (404) for an unknown id
        unit = self.units.get(sensor_id)
        if unit is None:
            raise HeadNotActiveError(not_driven(sensor))
        return unit

    def info(self, sensor_id: str) -> dict[str, Any]:
        """What :meth:`HeadUnit.info` says, for the API."""
        with self._lock:
            return self.unit(sensor_id).info()

    def slew(
        self, sensor_id: str, pan_deg: float, tilt_deg: float, hfov_deg: float | None
    ) -> dict[str, Any]:
        """Point a head (operator): mode ``slew``."""
        with self._lock:
            unit = self.unit(sensor_id)
            unit.adapter.absolute_move(pan_deg, tilt_deg, hfov_deg)
            self._set(
                unit, "slew", {"pan_deg": pan_deg, "tilt_deg": tilt_deg, "hfov_deg": hfov_deg}
            )
            return unit.info()

    def look(self, sensor_id: str, e_m: float, n_m: float, u_m: float | None) -> dict[str, Any]:
        """Point a head at a ground point (visibility checked): mode ``look``."""
        with self._lock:
            unit = self.unit(sensor_id)
            p, pan, tilt = check_ground_point(
                self.site, self._sensor_now(unit), e_m, n_m, u_m, unit.limits, self._hfov(unit)
            )
            unit.adapter.absolute_move(pan, tilt, None)
            target = {"e_m": float(p[0]), "n_m": float(p[1]), "u_m": float(p[2])}
            self._set(unit, "look", {**target, "pan_deg": pan, "tilt_deg": tilt})
            return unit.info()

    def follow(self, sensor_id: str, track_id: int) -> dict[str, Any]:
        """Assign a head to a live track: mode ``follow``."""
        with self._lock:
            unit = self.unit(sensor_id)
            # an operator's request may wait for a batch being processed (2 s at most)
            motion = (
                None if self.pipeline is None else track_motion(self.pipeline, track_id, wait_s=2.0)
            )
            if motion is None or motion.ended:
                raise NotFoundError(f"no live track {track_id} to follow")
            self._set(unit, "follow", {"track_id": int(track_id)})
            self._drive(unit)
            return unit.info()

    def release(self, sensor_id: str) -> dict[str, Any]:
        """Let a head go (it stops where it is): mode ``idle``."""
        with self._lock:
            unit = self.unit(sensor_id)
            unit.adapter.stop()
            self._set(unit, "idle", {})
            return unit.info()

    # ----------------------------------------------------------------- tick
    def tick(self) -> None:
        """Poll every head, feed the poses, drive followers, plan hand-offs."""
        with self._lock:
            self.n_ticks += 1
            for unit in self.units.values():
                self._poll(unit)
            now = self.clock()
            if now - self._fed_at >= self.feed_every_s:
                self._fed_at = now
                self.flush_poses()
            for unit in self.units.values():
                if unit.mode in ("follow", "handoff"):
                    self._drive(unit)
            self.planner.plan(self)

    def _poll(self, unit: HeadUnit) -> None:
        try:
            status = unit.adapter.status()
        except HeadAdapterError as exc:
            if unit.error != str(exc):
                log.warning("%s", exc)
            unit.error = str(exc)
            return
        unit.error = None
        age = self.clock() - status.t_s
        if 0.0 <= age < 5.0:  # a head whose clock is off says nothing about latency
            unit.latency_s += 0.2 * (age - unit.latency_s)
        if unit.status is None or status.t_s > unit.status.t_s:
            unit.unfed.append(status)
        unit.status = status

    def flush_poses(self) -> None:
        """Hand the statuses polled since the last flush to the pose feed, per head."""
        if self.feed is None:
            return
        for unit in self.units.values():
            if not unit.unfed:
                continue
            batch, unit.unfed = unit.unfed, []
            try:
                self.feed(unit.sensor_id, batch)
            except DemtrackError as exc:
                log.warning("poses of %s refused: %s", unit.sensor_id, exc)

    def _hfov(self, unit: HeadUnit) -> float | None:
        """The head's zoom for pointing: its field of view where the lens has a zoom table."""
        if unit.status is None or getattr(self.site.sensor(unit.sensor_id), "zoom", None) is None:
            return None
        return unit.status.hfov_deg

    def _sensor_now(self, unit: HeadUnit) -> Sensor:
        sensor = self.site.sensor(unit.sensor_id)
        if unit.status is None:
            return sensor
        return sensor_at(sensor, unit.status.pan_deg, unit.status.tilt_deg)

    def sensors_now(self) -> dict[str, Sensor]:
        """Every site sensor, the active ones at their last reported pan and tilt."""
        return {
            sid: self._sensor_now(self.units[sid]) if sid in self.units else s
            for sid, s in self.site.sensors.items()
        }

    def _drive(self, unit: HeadUnit) -> None:
        """Aim a following (or pre-positioned) head at its track."""
        if self.pipeline is None:
            return
        track_id = int(unit.target["track_id"])
        motion = track_motion(self.pipeline, track_id)
        if motion is None:
            return  # the pipeline is busy this tick (or the track is not known yet)
        if motion.ended:
            self._set(unit, "idle", {"reason": f"track {track_id} ended"})
            return
        if unit.mode == "handoff":
            if motion.t_s < float(unit.target.get("entry_t_s", -np.inf)):
                return  # hold the slew-ahead pose until the target is due
            self._set(unit, "follow", {"track_id": track_id, "from": unit.target.get("from")})
        release_t = unit.target.get("release_t_s")
        if release_t is not None and motion.t_s >= float(release_t):
            self._set(unit, "idle", {"reason": f"handed off to {unit.target.get('handed_to')}"})
            return
        lead = self.lead_s + self.period_s + unit.latency_s
        p = motion.at(motion.t_s + lead) + np.array([0.0, 0.0, TARGET_HEIGHT_M / 2])
        pan, tilt = aim_pan_tilt(self.site.sensor(unit.sensor_id), p, self._hfov(unit))
        goal = self._zoom_goal(unit, p) if unit.mode == "follow" else None
        zoom_moved = goal is not None and (
            unit.zoom_goal_deg is None or abs(goal - unit.zoom_goal_deg) > ZOOM_DEADBAND_DEG
        )
        if (
            not zoom_moved
            and unit.last_aim is not None
            and max(
                abs((pan - unit.last_aim[0] + 180.0) % 360.0 - 180.0), abs(tilt - unit.last_aim[1])
            )
            < DEADBAND_DEG
        ):
            return
        if zoom_moved:
            unit.zoom_goal_deg = goal
        try:
            unit.adapter.absolute_move(pan, tilt, unit.zoom_goal_deg)
            unit.last_aim = (pan, tilt)
        except HeadAdapterError as exc:
            unit.error = str(exc)

    def _zoom_goal(self, unit: HeadUnit, p_enu: np.ndarray) -> float | None:
        """The field of view a follower should zoom to (None: hold; no table or no band).

        The band rule on the share the target's :data:`TARGET_WIDTH_M` spans at its range
        through the lens at the head's present zoom; the goal stays within the head's
        limits and the lens's zoom table.
        """
        sensor = self.site.sensor(unit.sensor_id)
        zoom = getattr(sensor, "zoom", None)
        if self.zoom_band is None or zoom is None or unit.status is None:
            return None
        hfov = float(unit.status.hfov_deg)
        t_lo, t_hi = zoom.hfov_range_deg
        lo, hi = max(unit.limits.hfov_min_deg, t_lo), min(unit.limits.hfov_max_deg, t_hi)
        if lo > hi:
            return None  # the head cannot reach any zoom the lens is calibrated for
        base = sensor.head.intrinsics
        # Off the table (a head resting wider than the calibration): the ideal zoom.
        inside = t_lo <= hfov <= t_hi
        fx = (
            intrinsics_for_hfov(base, hfov, zoom).fx if inside else ideal_focal_px(base.width, hfov)
        )
        range_m = float(np.linalg.norm(np.asarray(p_enu) - sensor.head.position_enu))
        share = image_share(TARGET_WIDTH_M, range_m, fx, base.width)
        goal = zoom_to_band(hfov, share, self.zoom_band, (lo, hi))
        if not inside:  # whatever the band says, onto the calibrated range
            goal = min(max(goal, lo), hi)
        return goal if goal != hfov else unit.zoom_goal_deg

    # -------------------------------------------------------------- journal
    def _set(self, unit: HeadUnit, mode: str, target: dict[str, Any]) -> None:
        unit.mode, unit.target, unit.last_aim = mode, dict(target), None
        unit.zoom_goal_deg = None
        self.journal.append(
            {"t_s": self.clock(), "sensor_id": unit.sensor_id, "mode": mode, **target}
        )

    def assign_handoff(
        self,
        unit: HeadUnit,
        track_id: int,
        from_id: str,
        entry_t_s: float,
        aim: tuple[float, float] | None,
    ) -> None:
        """Hand ``unit`` a track another head is about to lose (the planner's call).

        With ``aim`` it slews there now and waits for the target (``handoff``); without,
        it already looks there and follows at once.
        """
        if aim is None:
            self._set(unit, "follow", {"track_id": track_id, "from": from_id})
            self._drive(unit)
            return
        unit.adapter.absolute_move(aim[0], aim[1], None)
        self._set(
            unit,
            "handoff",
            {
                "track_id": track_id,
                "from": from_id,
                "entry_t_s": entry_t_s,
                "pan_deg": aim[0],
                "tilt_deg": aim[1],
            },
        )

    def mark_release(self, unit: HeadUnit, handed_to: str, release_t_s: float) -> None:
        """Note when a following head lets go of its track, handed to another head."""
        target = {**unit.target, "handed_to": handed_to, "release_t_s": release_t_s}
        unit.mode, unit.target = "follow", target
        self.journal.append(
            {"t_s": self.clock(), "sensor_id": unit.sensor_id, "mode": "follow", **target}
        )

    def restore(self) -> None:
        """Apply each head's last journal row again (a hand-off resumes as a follow)."""
        for sensor_id, row in self.journal.last_by_sensor().items():
            unit = self.units.get(sensor_id)
            if unit is None:
                continue
            mode = row.get("mode")
            target = {k: v for k, v in row.items() if k not in ("t_s", "sensor_id", "mode")}
            try:
                if mode in ("slew", "look"):
                    unit.adapter.absolute_move(
                        target["pan_deg"], target["tilt_deg"], target.get("hfov_deg")
                    )
                    unit.mode, unit.target = mode, target
                elif mode in ("follow", "handoff"):
                    unit.mode, unit.target = mode, target
            except (HeadAdapterError, KeyError) as exc:
                log.warning("head %s: journal row not restored: %s", sensor_id, exc)
