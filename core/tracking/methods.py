"""The named tracking methods, their builders, and the batch entry point.

=====================  =====================================================================
name                   assembly
=====================  =====================================================================
``raw-first``          no filter, first hit (the baseline that jumps into trees)
``last-hit``           no filter, last hit (the VSAM paper's foliage heuristic)
``kalman``             constant-velocity Kalman filter, the hit nearest the prediction in
                       a chi-square gate; one tentative track per hit, best sibling wins
``multi-hypothesis``   CONDENSATION particle filter, likelihood a mixture over all hits
                       (with ``config.road_motion`` and roads: vehicles move on roads)
``multi-hypothesis-road``  the same with road-constrained vehicle motion (needs roads),
                       with an off-road mode (car parks, yards)
``road``               Kalman filter; vehicles use the road rule's hit (with roads: it and
                       the two lane centres along the ray, as a mixture), and a fix
                       without one (and every human fix) updates with the hit mixture
=====================  =====================================================================

Every method associates by global nearest neighbour with explicit missed detections,
confirms tracks M-of-N once their position has settled (the raw baselines: M-of-N
only), re-acquires lost vehicles along the roads, coasts through short occlusions,
and (except the raw baselines) triangulates simultaneous fixes from two cameras, lets no
fix whose ray passes through a confirmed track seed another track (the ray gate,
:mod:`.raygate`), and smooths its last
``config.smoothing_lag`` points (Rauch-Tung-Striebel for the Kalman filter, particle
ancestry for the particle filter; the newest point is always the filtered one).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from shapely import LineString

from ..errors import TrackingError
from .association import GlobalNearestNeighbour
from .config import TrackerConfig
from .deletion import CoastTimeDeleter
from .hypothesiser import GatedNearestHit, gate_d2
from .initiation import MOfNInitiator
from .kalman import KalmanFilter
from .measurement import AllHits, FirstHit, HitMixture, LastHit, RoadHit
from .motion import ConstantVelocity, ConstantVelocityParticles
from .particle import ParticleFilter
from .passthrough import PassThroughFilter
from .protocols import MeasurementModel, Reacquirer
from .reacquire import RoadFollowingReacquirer
from .roads import RoadGraph, RoadParticleMotion
from .tracker import ClassComponents, Tracker, TrackerComponents
from .types import CLASSES, Fix, Track

__all__ = ["METHODS", "Roads", "build_tracker", "run_tracker"]

Roads = RoadGraph | Sequence[LineString] | Any | None
Builder = Callable[[TrackerConfig, RoadGraph | None], TrackerComponents]


def _assemble(
    config: TrackerConfig,
    per_class: dict[str, ClassComponents],
    fuse: bool,
    ray_gate: bool | None = None,
) -> TrackerComponents:
    g = gate_d2(config.gate_probability)
    return TrackerComponents(
        per_class=per_class,
        hypothesiser=GatedNearestHit(g),
        associator=GlobalNearestNeighbour(miss_cost=g),
        deleter=CoastTimeDeleter({c: config.params(c).max_coast_s for c in CLASSES}),
        fuse=fuse,
        # The raw baselines (no fusion) keep plain hits' behaviour; the particle filters weigh
        # every hit along a ray themselves (and gated, they split a close convoy's pairs).
        ray_gate=fuse if ray_gate is None else ray_gate,
    )


def _reacquirer(cls: str, roads: RoadGraph | None) -> Reacquirer | None:
    """Vehicles near a road are re-acquired along it; the rest by their own prediction."""
    if roads is None or cls != "vehicle":
        return None
    return RoadFollowingReacquirer(roads.lines)


def _initiator(config: TrackerConfig, per_candidate: bool, settle: bool = True) -> MOfNInitiator:
    return MOfNInitiator(
        config.confirm_hits,
        config.confirm_window_s,
        per_candidate,
        config.confirm_spread_m if settle else None,
        config.confirm_settle_s,
    )


def _raw(measurement: MeasurementModel) -> Builder:
    def build(config: TrackerConfig, roads: RoadGraph | None) -> TrackerComponents:
        g = gate_d2(config.gate_probability)
        per_class = {
            c: ClassComponents(
                measurement,
                PassThroughFilter(_kalman_filter(config, c, smooth=False), config.raw_gate_m, g),
                _initiator(config, per_candidate=True, settle=False),
            )
            for c in CLASSES
        }
        return _assemble(config, per_class, fuse=False)

    return build


def _kalman_filter(config: TrackerConfig, cls: str, smooth: bool = True) -> KalmanFilter:
    p = config.params(cls)
    history = max(config.smoothing_lag + 1, config.confirm_hits) if smooth else 0
    return KalmanFilter(
        ConstantVelocity(p.q_m2_s3),
        p.init_speed_sigma_m_s,
        config.clutter_density_per_m2,
        history_len=history,
    )


def build_kalman(config: TrackerConfig, roads: RoadGraph | None) -> TrackerComponents:
    """Kalman filter on the hit nearest the prediction."""
    per_class = {
        c: ClassComponents(
            AllHits(), _kalman_filter(config, c), _initiator(config, True), _reacquirer(c, roads)
        )
        for c in CLASSES
    }
    return _assemble(config, per_class, fuse=True)


def _particle_filter(config: TrackerConfig, cls: str, roads: RoadGraph | None) -> ParticleFilter:
    p = config.params(cls)
    motion: ConstantVelocityParticles | RoadParticleMotion
    if roads is not None and cls == "vehicle":
        motion = RoadParticleMotion(
            roads,
            p.q_m2_s3,
            p.init_speed_sigma_m_s,
            leave_rate_per_s=config.road_leave_rate_per_s,
            join_rate_per_s=config.road_join_rate_per_s,
            p_free_init=config.road_free_init,
        )
    else:
        motion = ConstantVelocityParticles(p.q_m2_s3, p.init_speed_sigma_m_s)
    return ParticleFilter(
        motion,
        config.n_particles,
        config.clutter_density_per_m2,
        config.resample_ess_ratio,
        config.mode_radius_m,
        history_len=max(config.smoothing_lag + 1, config.confirm_hits),
    )


def _multi(
    config: TrackerConfig, roads: RoadGraph | None, reacquire_roads: RoadGraph | None
) -> TrackerComponents:
    per_class = {
        c: ClassComponents(
            HitMixture(),
            _particle_filter(config, c, roads),
            _initiator(config, per_candidate=False),
            _reacquirer(c, reacquire_roads),
        )
        for c in CLASSES
    }
    return _assemble(config, per_class, fuse=True, ray_gate=False)


def build_multi_hypothesis(config: TrackerConfig, roads: RoadGraph | None) -> TrackerComponents:
    """Particle filter over all hits; road motion only if ``config.road_motion``."""
    return _multi(config, roads if config.road_motion else None, roads)


def build_multi_hypothesis_road(
    config: TrackerConfig, roads: RoadGraph | None
) -> TrackerComponents:
    """Particle filter over all hits, vehicles constrained to the road network."""
    if roads is None:
        raise TrackingError("method 'multi-hypothesis-road' needs a road network (roads=...)")
    return _multi(config, roads, roads)


def build_road(config: TrackerConfig, roads: RoadGraph | None) -> TrackerComponents:
    """Kalman filter on the road rule's hit, the hit mixture (PDA) without one."""
    per_class = {
        "vehicle": ClassComponents(
            RoadHit(config.road_sigma_m, roads),
            _kalman_filter(config, "vehicle"),
            _initiator(config, True),
            _reacquirer("vehicle", roads),
        ),
        "human": ClassComponents(
            HitMixture(), _kalman_filter(config, "human"), _initiator(config, True)
        ),
    }
    return _assemble(config, per_class, fuse=True)


#: Method name -> builder ``(config, roads or None) -> TrackerComponents``.
METHODS: dict[str, Builder] = {
    "raw-first": _raw(FirstHit()),
    "last-hit": _raw(LastHit()),
    "kalman": build_kalman,
    "multi-hypothesis": build_multi_hypothesis,
    "multi-hypothesis-road": build_multi_hypothesis_road,
    "road": build_road,
}


def _network(roads: Roads) -> RoadGraph | None:
    if roads is None or isinstance(roads, RoadGraph):
        return roads
    # duck-typed: anything holding its centrelines as ``.lines`` (the site's
    # :class:`demtrack.core.geolocation.roads.RoadNetwork`), or the lines themselves
    lines = list(getattr(roads, "lines", roads))
    return RoadGraph(lines) if lines else None


def build_tracker(
    method: str, *, roads: Roads = None, config: TrackerConfig | None = None
) -> Tracker:
    """Build an online :class:`Tracker` for a named method.

    Parameters
    ----------
    method : str
        A key of :data:`METHODS`.
    roads : RoadGraph, sequence of shapely.LineString, or object with ``.lines``, optional
        Road centrelines in the local frame (m) (e.g. the site's
        :class:`demtrack.core.geolocation.roads.RoadNetwork`).
    config : TrackerConfig, optional
        Settings (defaults if None).
    """
    if method not in METHODS:
        raise TrackingError(f"unknown tracking method {method!r}; known: {sorted(METHODS)}")
    config = TrackerConfig() if config is None else config
    return Tracker(METHODS[method](config, _network(roads)), config)


def run_tracker(
    fixes: Sequence[Fix], method: str, *, roads: Roads = None, config: TrackerConfig | None = None
) -> list[Track]:
    """Track a batch of fixes.

    Parameters
    ----------
    fixes : sequence of Fix
        Fixes in any order; they are processed in time order (stable).
    method : str
        A key of :data:`METHODS`.
    roads : RoadGraph, sequence of shapely.LineString, or object with ``.lines``, optional
        Road centrelines in the local frame (m).
    config : TrackerConfig, optional
        Settings.

    Returns
    -------
    list of Track
        Confirmed tracks by id; :attr:`TrackPoint.fix_indices` index ``fixes``.
    """
    tracker = build_tracker(method, roads=roads, config=config)
    order = sorted(range(len(fixes)), key=lambda i: fixes[i].t_s)
    for i in order:
        tracker.update(fixes[i], index=i)
    return tracker.finish()
