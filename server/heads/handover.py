"""Hand-off planning: when a following head will lose its target, slew the next one ahead.

For each head in ``follow`` mode with no hand-off pending, about once a second:

1. :func:`~.aim.los_exit_s`: will this head lose its sight line to the target within
   ``ahead_s`` (8 s)? A following head keeps its target in view as long as it can see it, so its
   field of view does not end its watch -- its line of sight does. If not, nothing to do.
2. :func:`~demtrack.core.visibility.handoff.predict_handoff` with every sensor at its
   current pose names the next camera, when it will see the target and, for a head that
   must turn, the pan and tilt that centre the target at acquisition.
3. If that camera is an idle active head, its slew time
   (:func:`~demtrack.core.camera.head_motion.time_to_reach` from its state) plus a margin
   (the planning period and a second) is compared with the time to entry: once it covers
   it, the head is sent there and assigned the track; the current head is told when to let
   go (its predicted loss of sight). A head that already looks there follows at once.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

from demtrack.core.camera.head_motion import HeadState, time_to_reach
from demtrack.core.site.folder import Site
from demtrack.core.visibility.handoff import predict_handoff

from .aim import los_exit_s, track_motion

__all__ = ["HandoverPlanner"]


class HandoverPlanner:
    """Plans hand-offs for a :class:`~.controller.HeadController` (see the module docstring).

    ``plan`` takes the controller duck-typed (its ``units``, ``pipeline``,
    ``sensors_now``, ``assign_handoff``, ``mark_release``): the controller owns a
    planner, and the planner does not import the controller back.

    Parameters
    ----------
    site : Site
        The site.
    horizon_s, dt_s : float
        Prediction horizon and step (s).
    every_s : float
        Wall seconds between two plans for one head.
    margin_s : float
        Slack on top of the slew time (s).
    ahead_s : float
        Plan only for a head that will lose its sight line within this many seconds:
        earlier, the predictor's choice would be a guess far from the real exit.
    """

    def __init__(
        self,
        site: Site,
        *,
        horizon_s: float = 20.0,
        dt_s: float = 0.5,
        every_s: float = 1.0,
        margin_s: float = 1.0,
        ahead_s: float = 8.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.site = site
        self.horizon_s, self.dt_s, self.every_s, self.margin_s = horizon_s, dt_s, every_s, margin_s
        self.ahead_s = ahead_s
        self.clock = clock
        self._last: dict[str, float] = {}
        #: Every hand-off made: ``(from_id, to_id, track_id, entry_in_s, slew_s)``.
        self.history: list[tuple[str, str, int, float, float]] = []

    def plan(self, ctl: Any) -> None:
        """One planning pass over the following heads (the controller's lock is held)."""
        if ctl.pipeline is None or self.horizon_s <= 0:
            return
        now = self.clock()
        for unit in list(ctl.units.values()):
            if unit.mode != "follow" or "handed_to" in unit.target:
                continue
            if now - self._last.get(unit.sensor_id, -1e18) < self.every_s:
                continue
            self._last[unit.sensor_id] = now
            self._plan_one(ctl, unit)

    def _plan_one(self, ctl: Any, unit: Any) -> None:
        track_id = int(unit.target["track_id"])
        motion = track_motion(ctl.pipeline, track_id)
        if motion is None or motion.ended:
            return
        sensors = ctl.sensors_now()
        current = sensors[unit.sensor_id]
        exit_s = los_exit_s(
            self.site, current, motion, motion.t_s, horizon_s=self.horizon_s, dt_s=self.dt_s
        )
        if exit_s is None or exit_s > self.ahead_s:
            return  # it keeps its target for a while yet: no hand-off needed now
        # Fixed cameras may take the target where they already look, but only an active
        # idle head can be slewed: any other camera named for a slew is left out, ask again.
        candidates = dict(sensors)
        while True:
            pred = predict_handoff(
                self.site.dem,
                candidates,
                motion.at(motion.t_s),
                motion.v_enu,
                current=unit.sensor_id,
                horizon_s=self.horizon_s,
                dt_s=self.dt_s,
                roads=self.site.roads,
            )
            nxt_id = pred.next_sensor
            if nxt_id is None or not pred.slew:
                break
            if nxt_id in ctl.units and ctl.units[nxt_id].mode == "idle":
                break
            del candidates[pred.next_sensor]
        nxt = ctl.units.get(pred.next_sensor) if pred.next_sensor is not None else None
        if nxt is None or nxt.mode != "idle" or pred.next_in_s is None or nxt.status is None:
            return
        aim = None
        slew_s = 0.0
        if pred.slew and pred.pan_deg is not None and pred.tilt_deg is not None:
            s = nxt.status
            state = HeadState(s.t_s, s.pan_deg, s.tilt_deg, s.hfov_deg)
            slew_s = time_to_reach(state, pred.pan_deg, pred.tilt_deg, None, nxt.limits)
            if pred.next_in_s > slew_s + self.margin_s + self.every_s:
                return  # not yet: it would only wait there
            aim = (pred.pan_deg, pred.tilt_deg)
        ctl.assign_handoff(nxt, track_id, unit.sensor_id, motion.t_s + pred.next_in_s, aim)
        ctl.mark_release(unit, nxt.sensor_id, motion.t_s + max(exit_s, pred.next_in_s))
        self.history.append((unit.sensor_id, nxt.sensor_id, track_id, pred.next_in_s, slew_s))
