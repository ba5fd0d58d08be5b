"""Tracker settings: one frozen value with per-class motion parameters.

Every number has a unit in its name. Defaults suit ground vehicles and pedestrians seen
at 5-30 Hz from masts tens of metres high, with hit uncertainties of a few decimetres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields

from ..errors import TrackingError

__all__ = ["ClassParams", "TrackerConfig"]


@dataclass(frozen=True)
class ClassParams:
    """Motion parameters of one object class.

    Parameters
    ----------
    q_m2_s3 : float
        Spectral density of the white-noise acceleration of the constant-velocity model
        (m^2/s^3), per horizontal axis.
    init_speed_sigma_m_s : float
        1-sigma of each velocity component of a new track (m/s).
    max_coast_s : float
        A confirmed track with no associated fix for longer than this is deleted (s); below
        it the track coasts on its motion model and keeps its identity.
    """

    q_m2_s3: float
    init_speed_sigma_m_s: float
    max_coast_s: float

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not (math.isfinite(value) and value > 0):
                raise TrackingError(f"{f.name} must be a positive number, got {value}")


def _default_classes() -> dict[str, ClassParams]:
    return {
        "vehicle": ClassParams(q_m2_s3=3.0, init_speed_sigma_m_s=10.0, max_coast_s=4.0),
        "human": ClassParams(q_m2_s3=0.3, init_speed_sigma_m_s=1.5, max_coast_s=4.0),
    }


@dataclass(frozen=True)
class TrackerConfig:
    """Settings shared by every tracking method.

    Parameters
    ----------
    classes : dict of str to ClassParams
        Motion parameters per class ("vehicle", "human").
    gate_probability : float
        Probability mass of the chi-square (2 dof) validation gate on the Mahalanobis
        distance between a hit and a track's predicted position.
    confirm_hits : int
        M of the M-of-N rule: a tentative track is confirmed after this many fixes...
    confirm_window_s : float
        ...within this long after its first fix; otherwise it is dropped (s).
    confirm_spread_m : float or None
        ...and once its position is settled: the worst-direction 1-sigma of the state's
        position (all of it: a particle cloud split between hypotheses is not settled) at
        most this (m). Points made before it first settled are not reported. None: the
        plain M-of-N rule. Not used by the raw baselines.
    confirm_settle_s : float
        A tentative track with ``confirm_hits`` fixes is confirmed this long after its
        first fix even if not settled (s): an object only ever seen poorly is reported.
    gap_threshold_s : float
        A span with no associated fix longer than this is reported as a gap (s).
    step_window_s : float
        Fixes within this long of the first fix of a step are processed together, and
        only those can be triangulated with each other (s).
    fuse_sensors : bool
        Triangulate simultaneous fixes of the same object from two sensors.
    fusion_min_angle_deg : float
        Rays meeting at a smaller angle are not triangulated (poor geometry).
    fusion_max_miss_m : float
        Rays whose common perpendicular is longer than this are not the same object.
    fusion_hit_gate_sigma : float
        The triangulated point must lie within this many hit sigmas (plus 1 m) of a hit of
        each ray, horizontally, or the pair is a ghost.
    ray_sigma_rad : float
        1-sigma angular error of a viewing ray, used for the triangulated point's sigma.
    raw_gate_m : float
        Association radius of the raw (unfiltered) methods (m).
    road_sigma_m : float or None
        Sigma of a road-rule hit (m); None uses the smallest hit sigma of the fix.
    clutter_density_per_m2 : float
        Likelihood floor of the hit mixture: the density of a hit that is none of the
        object's (a tree crown, a false alarm), per square metre.
    n_particles : int
        Particles per track of the multi-hypothesis (CONDENSATION) filter.
    resample_ess_ratio : float
        Resample when the effective sample size falls below this fraction of the
        particles (1.0 = resample every update, as CONDENSATION does).
    smoothing_lag : int
        Track points up to this many updates old are re-estimated (Kalman: fixed-lag
        Rauch-Tung-Striebel; particles: from their ancestry; raw methods: never), so a
        point made while the hypotheses were still split is settled once motion has told
        them apart. The newest point is always the filtered one (what a live display
        shows).
    mode_radius_m : float
        The particle estimate is the mean of the particles within this radius of the
        densest cell, so separate hypotheses are not averaged into a point between them.
    road_motion : bool
        Multi-hypothesis method only: move vehicle particles along the road network when
        one is given.
    road_leave_rate_per_s : float
        Road-constrained particles leave the road network at this rate (1/s) into an
        off-road constant-velocity mode (car parks, yards); 0 with ``road_free_init`` 0:
        strictly on the roads.
    road_join_rate_per_s : float
        Off-road particles within the road's half width rejoin it at this rate (1/s).
    road_free_init : float
        Share of a new road track's particles near a road that start off-road (those
        farther than the road's half width always do).
    reacquire_s : float
        A track that ended (coasted past its class's ``max_coast_s``) stays this long a
        candidate identity for a new track (s; 0 disables): a newly confirmed track whose
        first fix comes after the old one's last takes the old id when the old track's
        motion model, predicted over the absence, gives its position a density above
        ``clutter_density_per_m2`` (the density of an unrelated object). On a road
        network the prediction follows the roads, so identity survives a long occlusion
        without a gate that grows over the fields.
    ray_gate_dz_m : float or None
        A single camera's fix that no confirmed track took, whose viewing ray passes
        through a confirmed track's gate (horizontally) within this height of the track's
        ground (m), is that track's object seen with its hits off it (a crest's far
        crossing, ground metres away along the ray): it neither feeds a tentative track
        nor seeds one (:mod:`.raygate`). None: every such fix may seed (the phantom
        tracks that shadow a real one along the ray come back).
    seed : int
        Seed of the particle filter's random generator.
    """

    classes: dict[str, ClassParams] = field(default_factory=_default_classes)
    gate_probability: float = 0.9999
    confirm_hits: int = 3
    confirm_window_s: float = 1.0
    confirm_spread_m: float | None = 1.5
    confirm_settle_s: float = 5.0
    gap_threshold_s: float = 1.0
    step_window_s: float = 0.02
    fuse_sensors: bool = True
    fusion_min_angle_deg: float = 10.0
    fusion_max_miss_m: float = 1.5
    fusion_hit_gate_sigma: float = 4.0
    ray_sigma_rad: float = 2e-3
    raw_gate_m: float = 20.0
    road_sigma_m: float | None = None
    clutter_density_per_m2: float = 1e-4
    n_particles: int = 400
    resample_ess_ratio: float = 0.5
    smoothing_lag: int = 5
    mode_radius_m: float = 3.0
    road_motion: bool = False
    road_leave_rate_per_s: float = 0.1
    road_join_rate_per_s: float = 1.0
    road_free_init: float = 0.05
    reacquire_s: float = 30.0
    ray_gate_dz_m: float | None = 3.0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("vehicle", "human"):
            if name not in self.classes:
                raise TrackingError(f"TrackerConfig.classes lacks parameters for {name!r}")
        if not 0.0 < self.gate_probability < 1.0:
            raise TrackingError(f"gate_probability must be in (0, 1), got {self.gate_probability}")
        if self.confirm_hits < 1:
            raise TrackingError(f"confirm_hits must be >= 1, got {self.confirm_hits}")
        if self.smoothing_lag < 0:
            raise TrackingError(f"smoothing_lag must be >= 0, got {self.smoothing_lag}")
        if self.n_particles < 10:
            raise TrackingError(f"n_particles must be >= 10, got {self.n_particles}")
        if not 0.0 < self.resample_ess_ratio <= 1.0:
            raise TrackingError("resample_ess_ratio must be in (0, 1]")
        positive = (
            "confirm_window_s",
            "gap_threshold_s",
            "fusion_min_angle_deg",
            "fusion_max_miss_m",
            "fusion_hit_gate_sigma",
            "ray_sigma_rad",
            "raw_gate_m",
            "clutter_density_per_m2",
            "mode_radius_m",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise TrackingError(f"{name} must be a positive number, got {value}")
        for name in ("road_leave_rate_per_s", "road_join_rate_per_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise TrackingError(f"{name} must be >= 0, got {value}")
        if not 0.0 <= self.road_free_init <= 1.0:
            raise TrackingError(f"road_free_init must be in [0, 1], got {self.road_free_init}")
        if not (math.isfinite(self.reacquire_s) and self.reacquire_s >= 0):
            raise TrackingError(f"reacquire_s must be >= 0, got {self.reacquire_s}")
        if not (math.isfinite(self.step_window_s) and self.step_window_s >= 0):
            raise TrackingError(f"step_window_s must be >= 0, got {self.step_window_s}")
        if self.confirm_spread_m is not None and not (
            math.isfinite(self.confirm_spread_m) and self.confirm_spread_m > 0
        ):
            raise TrackingError(
                f"confirm_spread_m must be positive or None, got {self.confirm_spread_m}"
            )
        if not (
            math.isfinite(self.confirm_settle_s) and self.confirm_settle_s >= self.confirm_window_s
        ):
            raise TrackingError("confirm_settle_s must be finite and >= confirm_window_s")
        if self.ray_gate_dz_m is not None and not (
            math.isfinite(self.ray_gate_dz_m) and self.ray_gate_dz_m > 0
        ):
            raise TrackingError(
                f"ray_gate_dz_m must be a positive number or None, got {self.ray_gate_dz_m}"
            )
        if self.road_sigma_m is not None and not self.road_sigma_m > 0:
            raise TrackingError(f"road_sigma_m must be positive or None, got {self.road_sigma_m}")

    def params(self, cls: str) -> ClassParams:
        """Motion parameters of class ``cls``."""
        try:
            return self.classes[cls]
        except KeyError:
            raise TrackingError(f"no motion parameters for class {cls!r}") from None
