"""Synthetic tracking scenarios: true paths, cameras on masts, noisy multi-hit fixes.

Used by the tests and the benchmarks; nothing here touches a real camera or DEM. The
terrain is the plane ``z = 0`` of the local frame. For each sensor frame and each visible,
detected target, the ray from the camera to the target's foot is perturbed by an angular
error, and its hit is where it meets the plane ``z = e`` (``e`` a DEM height error). With
probability ``p_tree`` the ray first passes a "tree crown" 5-15 m before the ground hit
(so the first hit is wrong), and with probability ``p_behind`` it meets a lower slope again
10-40 m beyond (so the right hit is a middle one). False alarms are uniform over an area.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from shapely import LineString, Polygon

from demtrack.core.errors import TrackingError
from demtrack.core.tracking.types import Fix, ObjectClass, TruthPath

__all__ = [
    "NoiseModel",
    "Scenario",
    "SyntheticSensor",
    "SyntheticTarget",
    "ellipse_road",
    "scenario_crossing",
    "scenario_loop",
    "scenario_pedestrians",
    "scenario_two_sensors",
    "simulate",
    "truth_along_line",
]


@dataclass(frozen=True)
class SyntheticSensor:
    """A camera on a mast.

    Parameters
    ----------
    name : str
        Sensor id.
    origin_enu : tuple of 3 float
        Camera centre (m).
    coverage : shapely.Polygon or None
        Where it sees the ground (None: everywhere).
    rate_hz : float
        Frame rate.
    phase_s : float
        Time of its first frame (s).
    """

    name: str
    origin_enu: tuple[float, float, float]
    coverage: Polygon | None = None
    rate_hz: float = 10.0
    phase_s: float = 0.0


@dataclass(frozen=True)
class NoiseModel:
    """Measurement errors and clutter.

    Parameters
    ----------
    ray_sigma_rad : float
        Angular 1-sigma of a viewing ray.
    dem_sigma_m : float
        1-sigma of the terrain height error at a hit (m).
    p_detect : float
        Probability that a visible target is detected in a frame.
    p_tree : float
        Probability that the ray passes a tree crown first.
    tree_range_m : tuple of 2 float
        Distance of the crown hit before the ground hit, along the ray (m).
    p_behind : float
        Probability of an extra hit beyond the ground hit.
    behind_range_m : tuple of 2 float
        Its distance beyond the ground hit (m).
    false_alarms_per_frame : float
        Mean number of false alarms per frame (Poisson).
    false_alarm_area : tuple of 4 float
        ``(x_min, y_min, x_max, y_max)`` where they fall (m).
    """

    ray_sigma_rad: float = 1e-3
    dem_sigma_m: float = 0.1
    p_detect: float = 0.95
    p_tree: float = 0.3
    tree_range_m: tuple[float, float] = (5.0, 15.0)
    p_behind: float = 0.15
    behind_range_m: tuple[float, float] = (10.0, 40.0)
    false_alarms_per_frame: float = 0.05
    false_alarm_area: tuple[float, float, float, float] = (-100.0, -100.0, 100.0, 100.0)


@dataclass(frozen=True)
class SyntheticTarget:
    """A target: its true path and whether it drives on a road (gets a road hit)."""

    truth: TruthPath
    on_road: bool = False


@dataclass(frozen=True, eq=False)
class Scenario:
    """A generated scenario.

    Parameters
    ----------
    fixes : tuple of Fix
        All fixes in time order (``detection_index`` = position).
    truths : tuple of TruthPath
        The targets' true paths.
    roads : tuple of shapely.LineString
        Road centrelines (may be empty).
    fix_target : ndarray, shape (n_fixes,)
        The true target id of each fix; -1 for false alarms.
    """

    fixes: tuple[Fix, ...]
    truths: tuple[TruthPath, ...]
    roads: tuple[LineString, ...]
    fix_target: np.ndarray


def ellipse_road(
    rx_m: float, ry_m: float, centre: tuple[float, float] = (0.0, 0.0), n: int = 180
) -> LineString:
    """Make a closed elliptical road centreline (counter-clockwise, starting east)."""
    a = np.linspace(0.0, 2 * np.pi, n + 1)
    a[-1] = 0.0
    return LineString(np.column_stack([centre[0] + rx_m * np.cos(a), centre[1] + ry_m * np.sin(a)]))


def truth_along_line(
    target_id: int,
    cls: ObjectClass,
    line: LineString,
    speed_m_s: float,
    t_start_s: float,
    t_end_s: float,
    *,
    start_m: float = 0.0,
    offset_m: float = 0.0,
    dt_s: float = 0.02,
) -> TruthPath:
    """Make a constant-speed path along ``line`` (wrapping if closed), offset to the left.

    A negative ``speed_m_s`` drives the line backwards; ``offset_m`` is relative to the
    line's own direction (left positive), so two lanes are ``+-offset``.
    """
    t = np.arange(t_start_s, t_end_s + 0.5 * dt_s, dt_s)
    length = line.length
    s = start_m + speed_m_s * (t - t_start_s)
    if line.is_closed:
        s = np.mod(s, length)
    elif np.any((s < 0) | (s > length)):
        raise TrackingError("the path runs off the end of an open line")
    centre = shapely.get_coordinates(shapely.line_interpolate_point(line, s))
    ahead = shapely.get_coordinates(
        shapely.line_interpolate_point(
            line, np.mod(s + 0.5, length) if line.is_closed else np.minimum(s + 0.5, length)
        )
    )
    behind = shapely.get_coordinates(
        shapely.line_interpolate_point(
            line, np.mod(s - 0.5, length) if line.is_closed else np.maximum(s - 0.5, 0.0)
        )
    )
    tangent = ahead - behind
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normal = np.column_stack([-tangent[:, 1], tangent[:, 0]])
    xy = centre + offset_m * normal
    return TruthPath(target_id, cls, t, np.column_stack([xy, np.zeros(len(t))]))


def _perpendiculars(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


def _fix_for_point(
    p_true: np.ndarray,
    sensor: SyntheticSensor,
    t: float,
    cls: ObjectClass,
    index: int,
    noise: NoiseModel,
    rng: np.random.Generator,
    road: bool,
) -> Fix | None:
    origin = np.asarray(sensor.origin_enu, dtype=np.float64)
    d = p_true - origin
    d /= np.linalg.norm(d)
    e1, e2 = _perpendiculars(d)
    d = d + noise.ray_sigma_rad * (rng.standard_normal() * e1 + rng.standard_normal() * e2)
    d /= np.linalg.norm(d)
    if d[2] >= -1e-3:
        return None  # the ray does not come down to the ground
    z_ground = p_true[2] + noise.dem_sigma_m * rng.standard_normal()
    t_hit = (z_ground - origin[2]) / d[2]
    ground = origin + t_hit * d
    sin_a = -d[2]
    tan_a = sin_a / math.sqrt(max(1.0 - sin_a * sin_a, 1e-12))
    lateral = noise.ray_sigma_rad * t_hit
    along = math.hypot(lateral / sin_a, noise.dem_sigma_m / tan_a)
    sigma = max(lateral, along, 0.05)
    hits = [ground]
    if rng.random() < noise.p_tree:
        back = min(rng.uniform(*noise.tree_range_m), 0.8 * t_hit)
        hits.insert(0, ground - back * d)
    if rng.random() < noise.p_behind:
        hits.append(ground + rng.uniform(*noise.behind_range_m) * d)
    return Fix(
        t_s=t,
        sensor=sensor.name,
        cls=cls,
        detection_index=index,
        origin_enu=origin,
        direction_enu=d,
        hits_enu=np.array(hits),
        hit_sigma_m=np.full(len(hits), sigma),
        road_hit_enu=ground if road else None,
        score=float(rng.uniform(0.5, 1.0)),
    )


def simulate(
    targets: Sequence[SyntheticTarget],
    sensors: Sequence[SyntheticSensor],
    noise: NoiseModel,
    *,
    t_end_s: float,
    seed: int = 0,
    roads: Sequence[LineString] = (),
) -> Scenario:
    """Generate the fixes of every sensor frame in ``[0, t_end_s]``.

    Parameters
    ----------
    targets : sequence of SyntheticTarget
        Targets (a target is visible while its path is defined).
    sensors : sequence of SyntheticSensor
        Cameras.
    noise : NoiseModel
        Errors and clutter.
    t_end_s : float
        End time (s).
    seed : int
        Random seed.
    roads : sequence of shapely.LineString
        Passed through to the scenario.
    """
    rng = np.random.default_rng(seed)
    frames = sorted(
        (float(t), k)
        for k, s in enumerate(sensors)
        for t in np.arange(s.phase_s, t_end_s + 1e-9, 1.0 / s.rate_hz)
    )
    fixes: list[Fix] = []
    owner: list[int] = []
    for t, k in frames:
        sensor = sensors[k]
        for tgt in targets:
            p = tgt.truth.at(t)[0]
            if not np.all(np.isfinite(p)):
                continue
            if sensor.coverage is not None and not sensor.coverage.contains(shapely.Point(p[:2])):
                continue
            if rng.random() >= noise.p_detect:
                continue
            road = tgt.on_road and tgt.truth.cls == "vehicle"
            fix = _fix_for_point(p, sensor, t, tgt.truth.cls, len(fixes), noise, rng, road)
            if fix is not None:
                fixes.append(fix)
                owner.append(tgt.truth.target_id)
        for _ in range(rng.poisson(noise.false_alarms_per_frame)):
            x0, y0, x1, y1 = noise.false_alarm_area
            p = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), 0.0])
            if sensor.coverage is not None and not sensor.coverage.contains(shapely.Point(p[:2])):
                continue
            cls: ObjectClass = "vehicle" if rng.random() < 0.5 else "human"
            fix = _fix_for_point(p, sensor, t, cls, len(fixes), noise, rng, False)
            if fix is not None:
                fixes.append(fix)
                owner.append(-1)
    return Scenario(
        tuple(fixes), tuple(t.truth for t in targets), tuple(roads), np.array(owner, dtype=np.int64)
    )


def scenario_loop(seed: int = 0, t_end_s: float = 40.0) -> Scenario:
    """Simulate one vehicle at 10 m/s on an 80 x 50 m elliptical loop.

    A camera on a 30 m mast in the middle; trees, far slopes, missed detections, false
    alarms.
    """
    road = ellipse_road(80.0, 50.0)
    car = truth_along_line(1, "vehicle", road, 10.0, 0.0, t_end_s, offset_m=-1.75)
    sensor = SyntheticSensor("cam0", (0.0, 0.0, 30.0))
    return simulate(
        [SyntheticTarget(car, on_road=True)],
        [sensor],
        NoiseModel(),
        t_end_s=t_end_s,
        seed=seed,
        roads=[road],
    )


def scenario_crossing(seed: int = 0, t_end_s: float = 18.0) -> Scenario:
    """Two vehicles passing each other in opposite lanes (3.5 m apart) of a straight road."""
    road = LineString([(-100.0, 0.0), (100.0, 0.0)])
    east = truth_along_line(1, "vehicle", road, 10.0, 0.0, t_end_s, start_m=10.0, offset_m=-1.75)
    west = truth_along_line(2, "vehicle", road, -10.0, 0.0, t_end_s, start_m=190.0, offset_m=1.75)
    sensor = SyntheticSensor("cam0", (0.0, 60.0, 30.0))
    targets = [SyntheticTarget(east, True), SyntheticTarget(west, True)]
    return simulate(targets, [sensor], NoiseModel(), t_end_s=t_end_s, seed=seed, roads=[road])


def scenario_pedestrians(seed: int = 0, t_end_s: float = 40.0) -> Scenario:
    """Three people walking off-road, two of them crossing paths; one camera, 5 Hz."""
    paths = [
        LineString([(-30.0, -20.0), (30.0, 20.0)]),
        LineString([(-30.0, 20.0), (30.0, -20.0)]),
        LineString([(-25.0, 30.0), (0.0, 30.0), (0.0, -5.0)]),
    ]
    speeds = (1.6, 1.7, 1.4)
    truths = [
        truth_along_line(i + 1, "human", line, v, 0.0, min(t_end_s, line.length / v))
        for i, (line, v) in enumerate(zip(paths, speeds, strict=True))
    ]
    sensor = SyntheticSensor("cam0", (0.0, -60.0, 25.0), rate_hz=5.0)
    noise = NoiseModel(false_alarm_area=(-40.0, -40.0, 40.0, 40.0))
    return simulate(
        [SyntheticTarget(t) for t in truths], [sensor], noise, t_end_s=t_end_s, seed=seed
    )


def scenario_two_sensors(seed: int = 0, t_end_s: float = 40.0) -> Scenario:
    """Simulate the loop vehicle and a pedestrian seen by two cameras.

    Camera ``west`` sees ``x < 10``, camera ``east`` sees ``x > -10`` (overlap: both see,
    so their rays are triangulated), except a patch in the north (``|x| < 12, y > 30``)
    nobody sees: a short honest gap the vehicle track must coast through. The cameras'
    frames are interleaved (east is 5 ms later).
    """
    road = ellipse_road(80.0, 50.0)
    car = truth_along_line(1, "vehicle", road, 10.0, 0.0, t_end_s, offset_m=-1.75)
    walk = truth_along_line(
        2, "human", LineString([(-5.0, -20.0), (5.0, 20.0)]), 1.0, 0.0, min(t_end_s, 40.0)
    )
    blind = shapely.box(-12.0, 30.0, 12.0, 200.0)
    west = shapely.box(-200.0, -200.0, 10.0, 200.0).difference(blind)
    east = shapely.box(-10.0, -200.0, 200.0, 200.0).difference(blind)
    sensors = [
        SyntheticSensor("west", (-40.0, 0.0, 30.0), west),
        SyntheticSensor("east", (40.0, 0.0, 30.0), east, phase_s=0.005),
    ]
    targets = [SyntheticTarget(car, True), SyntheticTarget(walk)]
    return simulate(targets, sensors, NoiseModel(), t_end_s=t_end_s, seed=seed, roads=[road])
