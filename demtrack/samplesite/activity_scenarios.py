"""Activity scenarios on the sample site: true events and near-misses for each detector.

Each case (:data:`ACTIVITY_CASES`) places targets on the analytic world (:mod:`.routes`,
:mod:`.world`) and states what really happens: the true events (kind, the targets by truth
id, the time interval) and the near-misses, situations built to come close to a
detector's threshold without crossing it. The targets are then seen by the real cameras
exactly as in :mod:`.scenarios` (true mount yaw, box sample points cast against the site
DEM, pixel noise, misses, false alarms), so the evaluation runs the whole chain:
detections -> fixes -> tracker -> detectors (:mod:`demtrack.samplesite.activity_eval`).

Cases (detector defaults: loitering R = 10 m, T = 60 s; rendezvous D = 5 m, T = 20 s;
convoy L = 100 m):

``loitering``
    Person 1 walks into the field, stands 40 s, steps 2.8 m and stands 35 s more
    (loitering, about 75 s); walking in and out it enters and leaves the "memorial" zone.
    Near-misses: person 2 lingers the same way for only 42 s in all (under T even with
    the walk in and out); person 3 paces 90 s up and down a 26 m line (never inside a
    10 m disc for 60 s); person 2 walks past the memorial zone 4 m outside it.
``rendezvous``
    Persons 1 and 2 walk from opposite sides, stop 1.5 m apart and stand together 30 s.
    Near-miss: persons 3 and 4 stop at the same time for 30 s, but 9 m apart.
``passing``
    The ``passing-vehicles`` cars: two cars in opposite lanes pass each other without
    stopping (no rendezvous, no convoy).
``convoy``
    Three cars drive in from the west entrance and round the loop's south side, 3 s
    apart (24 m at 8 m/s): one convoy. Each enters and leaves the "south gate" zone.
``convoy-uneven``
    Near-miss: two cars on the same route 2 s apart, but the second cruises at 4 m/s
    against the first's 8 m/s: the spacing grows from 16 m to over 100 m.
``convoy-short``
    Near-miss: two cars 3 s apart down the entrance road; at the loop one turns south,
    the other north, so they share under 100 m.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import shapely

from demtrack.core.activity.zones import Zone
from demtrack.core.errors import SiteError
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import TruthPath

from .routes import Motion, Route, drive, offset_lane, resample_polyline, smooth_polyline
from .scenarios import (
    LANE_OFFSET_M,
    SCENARIOS,
    SIZES_M,
    Scenario,
    ScenarioParams,
    Target,
    _truth,
    render_targets,
    site_world,
)
from .world import World

__all__ = [
    "ACTIVITY_CASES",
    "DEFAULT_ACTIVITY_PARAMS",
    "ActivityCase",
    "ActivityScenario",
    "NearMiss",
    "TrueEvent",
    "make_activity_scenario",
    "render_targets",
    "truth_paths",
]

#: Detections for the activity cases: 5 Hz is plenty for behaviour over tens of seconds
#: and halves the work of the 10 Hz tracking scenarios.
DEFAULT_ACTIVITY_PARAMS = ScenarioParams(rate_hz=5.0)


@dataclass(frozen=True)
class TrueEvent:
    """An activity that really happens.

    Attributes
    ----------
    kind : str
        ``loitering``, ``rendezvous``, ``convoy``, ``zone-enter`` or ``zone-leave``.
    target_ids : tuple of int
        Truth target ids involved (a convoy lists the leader first).
    t_start_s, t_end_s : float
        When it holds (s; equal for a zone crossing).
    note : str
        What happens, in words.
    """

    kind: str
    target_ids: tuple[int, ...]
    t_start_s: float
    t_end_s: float
    note: str = ""

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form."""
        return {
            "kind": self.kind,
            "target_ids": list(self.target_ids),
            "t_start_s": round(self.t_start_s, 2),
            "t_end_s": round(self.t_end_s, 2),
            "note": self.note,
        }


@dataclass(frozen=True)
class NearMiss:
    """A situation close to a detector's threshold that must not fire.

    It fires when the detector reports an event of ``kind`` whose targets include all of
    ``target_ids``.
    """

    kind: str
    target_ids: tuple[int, ...]
    note: str


@dataclass(frozen=True, eq=False)
class ActivityCase:
    """One case's set-up: targets, zones, true events and near-misses."""

    targets: tuple[Target, ...]
    events: tuple[TrueEvent, ...]
    near_misses: tuple[NearMiss, ...]
    zones: tuple[Zone, ...] = ()


@dataclass(frozen=True, eq=False)
class ActivityScenario:
    """A rendered activity case: detections and truth paths, plus its events."""

    name: str
    scenario: Scenario
    case: ActivityCase


# ---------------------------------------------------------------- motion helpers
HUMAN_SPEED_M_S = 1.4


def _walk(
    waypoints: Sequence[tuple[float, float]],
    dwell_s: Sequence[float],
    *,
    t0_s: float = 0.0,
    speed_m_s: float = HUMAN_SPEED_M_S,
) -> Motion:
    """Walk straight from waypoint to waypoint, standing ``dwell_s[k]`` at waypoint ``k``.

    ``dwell_s`` has one entry per waypoint (0 = walk on; the first and last are ignored).
    """
    pts = np.asarray(waypoints, dtype=np.float64)
    legs = np.hypot(*np.diff(pts, axis=0).T)
    s_way = np.r_[0.0, np.cumsum(legs)]
    xy = resample_polyline(pts, 0.25)
    stops = tuple(
        (float(s_way[k]), float(dwell_s[k])) for k in range(1, len(pts) - 1) if dwell_s[k] > 0
    )
    return drive(
        Route(xy, stops=stops),
        t0_s=t0_s,
        cruise_m_s=speed_m_s,
        lateral_acc_m_s2=1.0,
        acc_m_s2=0.5,
        start_speed_m_s=speed_m_s,
        end_speed_m_s=speed_m_s,
    )


def _dwells(motion: Motion) -> list[tuple[float, float]]:
    """Intervals ``(t0, t1)`` (s) where the target stands still, in order."""
    t, s = motion.t_s, motion.s_m
    idx = np.flatnonzero((np.diff(s) == 0) & (np.diff(t) > 0))
    return [(float(t[i]), float(t[i + 1])) for i in idx]


def _human(target_id: int, motion: Motion) -> Target:
    return Target(target_id, "human", motion, SIZES_M["human"])


def _car(target_id: int, motion: Motion) -> Target:
    return Target(target_id, "vehicle", motion, SIZES_M["vehicle"])


def _zone_crossings(
    target_id: int, motion: Motion, zone: Zone, dt_s: float = 0.05
) -> list[TrueEvent]:
    """True entries/exits of ``zone`` along ``motion``, sampled every ``dt_s`` (s).

    The crossing time is the midpoint between the last sample on one side and the first on
    the other, so it is good to ``dt_s / 2`` (an oracle independent of the detector's
    boundary interpolation).
    """
    t = np.arange(motion.t_start, motion.t_end + 1e-9, dt_s)
    xy, _ = motion.pose(t)
    inside = shapely.contains_xy(zone.polygon, xy[:, 0], xy[:, 1])
    out = []
    for k in np.flatnonzero(inside[1:] != inside[:-1]):
        tc = float((t[k] + t[k + 1]) / 2)
        kind = "zone-enter" if inside[k + 1] else "zone-leave"
        out.append(TrueEvent(kind, (target_id,), tc, tc, f"target {target_id}: {zone.name}"))
    return out


def _box(x0: float, y0: float, x1: float, y1: float) -> shapely.Polygon:
    return shapely.box(x0, y0, x1, y1)


# ---------------------------------------------------------------- the cases
def _loitering(world: World) -> ActivityCase:
    # Person 1: in from the north-west, 40 s at A, a step, 35 s at B, out to the south-east.
    p1 = _walk(
        [(-72.0, 35.0), (-45.0, 20.0), (-43.0, 22.0), (-25.0, 0.0)],
        [0.0, 40.0, 35.0, 0.0],
        t0_s=0.0,
    )
    # Person 2: the same kind of lingering but 18 s + 14 s: under T with the walk in/out.
    p2 = _walk(
        [(-85.0, -45.0), (-62.0, -20.0), (-60.0, -18.0), (-60.0, 30.0)],
        [0.0, 18.0, 14.0, 0.0],
        t0_s=5.0,
    )
    # Person 3: paces a 26 m line three times (half-diagonal 13 m > R), about 90 s.
    a, b = (-20.0, 35.0), (6.0, 35.0)
    p3 = _walk([a, b, a, b], [0.0, 0.5, 0.5, 0.0], t0_s=3.0, speed_m_s=0.9)
    memorial = Zone("memorial", _box(-56.0, 14.0, -37.0, 28.0))
    (a1, _), (_, b1) = _dwells(p1)[0], _dwells(p1)[-1]
    events = (
        TrueEvent("loitering", (1,), a1, b1, "person 1 stands about 75 s within 2 m"),
        *_zone_crossings(1, p1, memorial),
    )
    near = (
        NearMiss("loitering", (2,), "person 2 stands 32 s, within 10 m for 53 s (T = 60 s)"),
        NearMiss("loitering", (3,), "person 3 paces a 26 m line for 90 s (R = 10 m)"),
        NearMiss("zone-enter", (2,), "person 2 passes 4 m outside the memorial zone"),
        NearMiss("zone-enter", (3,), "person 3 paces 7 m from the memorial zone"),
    )
    return ActivityCase((_human(1, p1), _human(2, p2), _human(3, p3)), events, near, (memorial,))


def _rendezvous(world: World) -> ActivityCase:
    meet = np.array([-40.0, 10.0])
    # Persons 1 and 2 from opposite sides, arriving a few seconds apart.
    p1 = _walk([(-85.0, -20.0), tuple(meet), (-80.0, 40.0)], [0.0, 30.0, 0.0], t0_s=0.0)
    p2 = _walk([(5.0, 40.0), tuple(meet + [1.5, 0.0]), (0.0, -30.0)], [0.0, 30.0, 0.0], t0_s=2.0)
    # Persons 3 and 4 stop at the same time, 9 m apart.
    p3 = _walk([(-80.0, -45.0), (-55.0, -25.0), (-30.0, -50.0)], [0.0, 28.0, 0.0], t0_s=0.0)
    p4 = _walk([(-10.0, -45.0), (-46.0, -25.0), (-15.0, -10.0)], [0.0, 28.0, 0.0], t0_s=0.0)
    (d1,), (d2,) = _dwells(p1), _dwells(p2)
    events = (
        TrueEvent(
            "rendezvous",
            (1, 2),
            max(d1[0], d2[0]),
            min(d1[1], d2[1]),
            "persons 1 and 2 stand 1.5 m apart",
        ),
    )
    near = (NearMiss("rendezvous", (3, 4), "persons 3 and 4 both stand 28 s, 9 m apart (D = 5 m)"),)
    targets = (_human(1, p1), _human(2, p2), _human(3, p3), _human(4, p4))
    return ActivityCase(targets, events, near)


def _passing(world: World) -> ActivityCase:
    targets = tuple(SCENARIOS["passing-vehicles"](world))
    near = (
        NearMiss("rendezvous", (1, 2), "the two cars pass each other without stopping"),
        NearMiss("convoy", (1, 2), "the two cars drive in opposite directions"),
    )
    return ActivityCase(targets, (), near)


def _south_route(world: World) -> np.ndarray:
    """Right-hand lane from the west entrance round the loop's south side (m, (n, 2))."""
    return SCENARIOS["passing-vehicles"](world)[0].motion.route.xy


def _convoy(world: World) -> ActivityCase:
    route = Route(_south_route(world))
    cars = tuple(_car(k + 1, drive(route, t0_s=3.0 * k, cruise_m_s=8.0)) for k in range(3))
    gate = Zone("south gate", _box(-45.0, -80.0, -25.0, -50.0))
    motions = [c.motion for c in cars]
    events = [
        TrueEvent(
            "convoy",
            (1, 2, 3),
            max(m.t_start for m in motions),
            min(m.t_end for m in motions),
            "three cars 3 s apart along the entrance and the south side",
        )
    ]
    for c in cars:
        events += _zone_crossings(c.target_id, c.motion, gate)
    return ActivityCase(cars, tuple(events), (), (gate,))


def _convoy_uneven(world: World) -> ActivityCase:
    route = Route(_south_route(world))
    cars = (
        _car(1, drive(route, t0_s=0.0, cruise_m_s=8.0)),
        _car(2, drive(route, t0_s=2.0, cruise_m_s=4.0)),
    )
    near = (NearMiss("convoy", (1, 2), "same route, but the spacing grows from 16 m to 100 m"),)
    return ActivityCase(cars, (), near)


def _convoy_short(world: World) -> ActivityCase:
    loop, ent = world.roads["loop"], world.roads["entrance"]
    j_ent = int(np.argmin(np.hypot(*(loop - ent[-1]).T)))
    n = len(loop) - 1
    south = [loop[(j_ent + k) % n] for k in range(0, 45)]
    north = [loop[(j_ent - k) % n] for k in range(0, 45)]
    paths = []
    for arm in (south, north):
        line = smooth_polyline(np.vstack([ent, np.array(arm)]), 8.0)
        paths.append(resample_polyline(offset_lane(line, LANE_OFFSET_M), 0.5))
    cars = (
        _car(1, drive(Route(paths[0]), t0_s=0.0, cruise_m_s=8.0)),
        _car(2, drive(Route(paths[1]), t0_s=3.0, cruise_m_s=8.0)),
    )
    shared = float(np.sum(np.hypot(*np.diff(ent, axis=0).T)))
    near = (
        NearMiss(
            "convoy", (1, 2), f"3 s apart for the entrance road only ({shared:.0f} m < L = 100 m)"
        ),
    )
    return ActivityCase(cars, (), near)


#: Case name -> set-up on a world.
ACTIVITY_CASES: dict[str, Callable[[World], ActivityCase]] = {
    "loitering": _loitering,
    "rendezvous": _rendezvous,
    "passing": _passing,
    "convoy": _convoy,
    "convoy-uneven": _convoy_uneven,
    "convoy-short": _convoy_short,
}


# ---------------------------------------------------------------- rendering
def truth_paths(case: ActivityCase, world: World, dt_s: float = 0.05) -> list[TruthPath]:
    """The true paths of a case's targets, sampled every ``dt_s`` (s), without rendering."""
    return [_truth(tg, world, dt_s) for tg in case.targets]


def make_activity_scenario(
    site: Site, name: str, params: ScenarioParams | None = None
) -> ActivityScenario:
    """Build an activity case's detections, truth and events on a sample site.

    Parameters
    ----------
    site : Site
        A folder written by :func:`demtrack.samplesite.build.build_sample_site`.
    name : str
        A key of :data:`ACTIVITY_CASES`.
    params : ScenarioParams, optional
        Noise, misses, false alarms, seed, frame rate (default
        :data:`DEFAULT_ACTIVITY_PARAMS`).

    Raises
    ------
    SiteError
        Unknown case, or a site that is not a generated sample site.
    """
    if name not in ACTIVITY_CASES:
        raise SiteError(f"unknown activity case {name!r}; known: {', '.join(ACTIVITY_CASES)}")
    world = site_world(site)
    case = ACTIVITY_CASES[name](world)
    scenario = render_targets(
        site, world, name, case.targets, DEFAULT_ACTIVITY_PARAMS if params is None else params
    )
    return ActivityScenario(name, scenario, case)
