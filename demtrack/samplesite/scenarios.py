"""Tracking scenarios on the sample site, with ground truth.

True 3-D target paths (:mod:`.routes` on the analytic world's roads and ground) are
projected into each camera with the real camera model (:mod:`.scene_render`): the site's
pan-tilt head with the **true** mount yaw from ``truth.json`` (the site stores the
calibrated one, so the calibration error is part of the experiment). A target is a box
(vehicle 4.5 x 1.8 x 1.5 m along its heading, human 0.5 x 0.5 x 1.8 m); its image box is
the bounding box of the projections of the sample points on its surface that the camera
sees: a ray from the camera to each point is cast against the site DEM (a first-return
surface, so tree crowns and roofs occlude), and points behind the surface are dropped.
Where a crown hides the lower part of a vehicle, the box bottom rises onto the crown - the
VSAM paper's failure mode. Boxes then get pixel noise on each edge; detections are missed
at random and false alarms appear at random. Everything is deterministic for a seed.

Scenarios (:data:`SCENARIOS`):

``vehicle-run``
    The paper's run: a car drives in from the west entrance, round the loop's south side
    to the south-east, down the spur into the parking lot, stops, turns around, drives
    back up and continues counter-clockwise round the loop (east side unseen, then the
    north and west sides). Seen by all three cameras in turn, with hand-off gaps.
``pedestrians``
    Three people crossing the field, two of them crossing each other's path.
``passing-vehicles``
    Two cars in opposite lanes passing each other at the loop's south-west corner.
``active-handoff``
    The vehicle-run's car, seen by the three cameras acting as pan-tilt-zoom heads that
    follow it and hand it over (:mod:`.active_scenario`); the scenario carries each
    head's pose telemetry (:attr:`Scenario.poses`). One of :data:`ACTIVE_SCENARIOS`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

import numpy as np

from demtrack.core.errors import InputFileError, SiteError
from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import TruthPath

from .active_scenario import ActiveParams, make_active_scenario
from .routes import Route, drive, offset_lane, resample_polyline, smooth_polyline
from .scene_render import (
    SIZES_M,
    Scenario,
    ScenarioParams,
    Target,
    image_boxes,
    render_targets,
    site_world,
    target_points,
    true_cameras,
    truth_path,
)
from .world import World

__all__ = [
    "ACTIVE_SCENARIOS",
    "LANE_OFFSET_M",
    "SCENARIOS",
    "SIZES_M",
    "Scenario",
    "ScenarioParams",
    "Target",
    "image_boxes",
    "site_world",
    "make_scenario",
    "render_targets",
    "read_truth_json",
    "target_points",
    "true_cameras",
    "write_truth_json",
]

LANE_OFFSET_M = 1.5  # right-hand traffic: a car drives this far right of the centreline
_truth = truth_path  # the activity scenarios' name for it


# ---------------------------------------------------------------- the routes
def _loop_span(loop: np.ndarray, i0: int, i1: int, step: int = 1) -> np.ndarray:
    """Loop vertices from index ``i0`` to ``i1`` going ``step`` (+1 counter-clockwise)."""
    n = len(loop) - 1  # the polyline is closed: the last vertex repeats the first
    out, i = [], i0 % n
    while True:
        out.append(loop[i])
        if i == i1 % n:
            break
        i = (i + step) % n
    return np.array(out)


def _nearest(poly: np.ndarray, xy: tuple[float, float]) -> int:
    return int(np.argmin(np.hypot(poly[:, 0] - xy[0], poly[:, 1] - xy[1])))


def _concat(*parts: np.ndarray) -> np.ndarray:
    return resample_polyline(np.vstack(parts), 0.5)


def _vehicle_run(world: World) -> list[Target]:
    loop, ent, spur = world.roads["loop"], world.roads["entrance"], world.roads["parking spur"]
    j_ent = _nearest(loop, tuple(ent[-1]))
    j_spur = _nearest(loop, tuple(spur[0]))
    end = spur[-1]
    heading = (spur[-1] - spur[-2]) / np.linalg.norm(spur[-1] - spur[-2])
    right = np.array([heading[1], -heading[0]])
    radius = 6.0
    centre = end + radius * right
    phi = np.linspace(0, np.pi, 25)[1:]
    # Turn round to the right in the lot: a half circle, clockwise, from the spur's end.
    rel = -radius * right
    cw = np.column_stack(
        [
            rel[0] * np.cos(phi) + rel[1] * np.sin(phi),
            -rel[0] * np.sin(phi) + rel[1] * np.cos(phi),
        ]
    )
    u_turn = centre + cw
    back_from = _nearest(spur, (100.0, -100.0))
    approach = _concat(ent, _loop_span(loop, j_ent, j_spur, +1), spur)
    leave = _concat(spur[back_from::-1], _loop_span(loop, j_spur, j_ent + 30, +1))
    centre_line = smooth_polyline(np.vstack([approach, u_turn, leave]), 8.0)
    xy = resample_polyline(offset_lane(centre_line, LANE_OFFSET_M), 0.5)
    s = Route(xy).s_m
    # The stop: where the lane passes the spur's end, on the way in.
    n_in = len(approach) + 10
    s_end = float(s[_nearest(xy[:n_in], tuple(end + LANE_OFFSET_M * right))])
    spur_len = float(np.sum(np.hypot(*np.diff(spur, axis=0).T)))
    lot0, lot1 = s_end - 40.0, s_end + np.pi * radius + 40.0
    motion = drive(
        Route(xy, stops=((s_end, 5.0),)),
        cruise_m_s=8.0,
        speed_limits=((s_end - spur_len, lot0, 6.0), (lot0, lot1, 4.0)),
    )
    return [Target(1, "vehicle", motion, SIZES_M["vehicle"])]


def _walk(a: tuple[float, float], b: tuple[float, float], wiggle_m: float) -> np.ndarray:
    pa, pb = np.array(a), np.array(b)
    t = np.linspace(0, 1, 200)
    d = pb - pa
    side = np.array([d[1], -d[0]]) / np.linalg.norm(d)
    xy = pa + t[:, None] * d + (wiggle_m * np.sin(2 * np.pi * 1.5 * t))[:, None] * side
    return resample_polyline(xy, 0.25)


def _pedestrians(world: World) -> list[Target]:
    walks = [
        ((-85.0, -45.0), (-25.0, 50.0), 1.4, 0.0, 2.0),
        ((-30.0, -50.0), (-85.0, 40.0), 1.3, 4.0, 1.5),
        ((-60.0, 60.0), (10.0, -15.0), 1.5, 8.0, 1.0),
    ]
    out = []
    for k, (a, b, speed, t0, wiggle) in enumerate(walks, start=1):
        motion = drive(
            Route(_walk(a, b, wiggle)),
            t0_s=t0,
            cruise_m_s=speed,
            lateral_acc_m_s2=1.0,
            acc_m_s2=0.5,
        )
        out.append(Target(k, "human", motion, SIZES_M["human"]))
    return out


def _passing_vehicles(world: World) -> list[Target]:
    loop, ent = world.roads["loop"], world.roads["entrance"]
    j_ent = _nearest(loop, tuple(ent[-1]))
    j_south = _nearest(loop, (0.0, -70.0))
    j_north = _nearest(loop, (-60.0, 95.0))
    a_line = smooth_polyline(np.vstack([ent, _loop_span(loop, j_ent, j_south, +1)]), 8.0)
    b_line = smooth_polyline(_loop_span(loop, j_south, j_north, -1), 8.0)
    a_path = resample_polyline(offset_lane(a_line, LANE_OFFSET_M), 0.5)
    b_path = resample_polyline(offset_lane(b_line, LANE_OFFSET_M), 0.5)
    a = drive(Route(a_path), cruise_m_s=8.0)
    b = drive(Route(b_path), t0_s=2.0, cruise_m_s=7.0)
    return [
        Target(1, "vehicle", a, SIZES_M["vehicle"]),
        Target(2, "vehicle", b, SIZES_M["vehicle"]),
    ]


#: Scenario name -> targets on a world.
SCENARIOS: dict[str, Callable[[World], list[Target]]] = {
    "vehicle-run": _vehicle_run,
    "pedestrians": _pedestrians,
    "passing-vehicles": _passing_vehicles,
    "active-handoff": _vehicle_run,
}
#: The scenarios whose cameras are pan-tilt-zoom heads following the targets.
ACTIVE_SCENARIOS: frozenset[str] = frozenset({"active-handoff"})


def make_scenario(
    site: Site,
    name: str,
    params: ScenarioParams | None = None,
    *,
    fixed_cameras: bool = False,
    active: ActiveParams | None = None,
) -> Scenario:
    """Build a scenario's detections and truth on a sample site.

    Parameters
    ----------
    site : Site
        A folder written by :func:`demtrack.samplesite.build.build_sample_site`.
    name : str
        A key of :data:`SCENARIOS`.
    params : ScenarioParams, optional
        Noise, misses, false alarms, seed.
    fixed_cameras : bool
        For an active scenario (:data:`ACTIVE_SCENARIOS`): leave the heads at their
        stored pan and tilt instead (the same targets, seen as by fixed cameras).
    active : ActiveParams, optional
        For an active scenario: the heads' telemetry and control settings.

    Raises
    ------
    SiteError
        Unknown scenario, or a site that is not a generated sample site.
    """
    if name not in SCENARIOS:
        raise SiteError(f"unknown scenario {name!r}; known: {', '.join(sorted(SCENARIOS))}")
    params = ScenarioParams() if params is None else params
    world = site_world(site)
    targets = SCENARIOS[name](world)
    if name in ACTIVE_SCENARIOS and not fixed_cameras:
        return make_active_scenario(site, world, name, targets, params, active)
    return render_targets(site, world, name, targets, params)


# ---------------------------------------------------------------- truth files
def write_truth_json(path: str | Path, scenario: Scenario) -> None:
    """Write a scenario's ground truth (format ``demtrack.truth`` version 1)."""
    doc = {
        "format": "demtrack.truth",
        "version": 1,
        "scenario": scenario.name,
        "params": asdict(scenario.params),
        "frame": "site ENU (x east, y north, z up; m); t in s",
        "stats": scenario.stats,
        "targets": [
            {
                "target_id": tr.target_id,
                "class": tr.cls,
                "t_s": [round(float(x), 4) for x in tr.t_s],
                "p_enu": [[round(float(x), 4) for x in p] for p in tr.p_enu],
            }
            for tr in scenario.truths
        ],
    }
    Path(path).write_text(json.dumps(doc), "utf-8")


def read_truth_json(path: str | Path) -> list[TruthPath]:
    """Read :func:`write_truth_json` output back into true paths."""
    try:
        doc = json.loads(Path(path).read_text("utf-8"))
    except (OSError, json.JSONDecodeError) as err:
        raise InputFileError(f"cannot read truth file {path}: {err}") from None
    if not isinstance(doc, dict) or doc.get("format") != "demtrack.truth":
        raise InputFileError(f"{path} is not a demtrack truth file")
    return [
        TruthPath(int(t["target_id"]), t["class"], np.array(t["t_s"]), np.array(t["p_enu"]))
        for t in doc["targets"]
    ]
