"""Why a track has a gap: outside every field of view, occluded, or missed detections.

A gap (:attr:`~demtrack.core.tracking.types.Track.gaps`) is a stretch with no fix. Along
the target's path across it (by default the straight line between the track's last point
before and first point after; any ``path(t_s) -> p_enu`` may be given, e.g. a road-following
prediction), every ``dt_s`` the standing target (``height_m`` tall) is tested against each
camera:

``outside-fov``
    No camera's image contains any part of the target.
``occluded``
    Some camera has it in its image, but none sees ``min_fraction`` of its height: the
    sight lines are blocked. The blocking point is the first surface crossing of the
    sight line to the target's middle (:func:`~demtrack.core.raycast.cast.cast_rays`), and it is
    called ``object`` (a building or a tree: it stands more than ``object_min_m`` above the
    lowest DEM cell within ``ground_window_m``, a bare-earth estimate from the first-return
    DEM) or ``terrain``.
``missed``
    Some camera has it in view and sees enough of it: the detector missed it.

The gap's ``reason`` is the class that holds for most of its samples; ``shares`` gives all
three.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..camera.pinhole import Camera
from ..errors import TrackingError
from ..raycast.cast import cast_rays
from ..terrain.dem import Dem
from .target_heights import target_height_for
from .viewshed import target_visible_fraction

__all__ = ["REASONS", "GapExplanation", "Occlusion", "explain_gap", "explain_track_gaps"]

#: The three reasons, in the order ties are broken.
REASONS = ("outside-fov", "occluded", "missed")


@dataclass(frozen=True)
class Occlusion:
    """What blocks one camera's sight line to the target.

    Attributes
    ----------
    sensor : str
    t_s : float
        When (a sample inside the gap).
    p_enu : ndarray, shape (3,)
        The blocking point: first surface crossing of the sight line, site frame (m).
    kind : {"object", "terrain"}
        A building or tree (well above the local ground), or the ground itself.
    above_ground_m : float
        Height of the blocking point above the local ground estimate (m).
    """

    sensor: str
    t_s: float
    p_enu: np.ndarray
    kind: str
    above_ground_m: float

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "sensor": self.sensor,
            "t_s": self.t_s,
            "p_enu": [round(float(v), 3) for v in self.p_enu],
            "kind": self.kind,
            "above_ground_m": round(self.above_ground_m, 2),
        }


@dataclass(frozen=True)
class GapExplanation:
    """Why one gap happened.

    Attributes
    ----------
    t_start_s, t_end_s : float
        The gap.
    reason : str
        One of :data:`REASONS`: what held for most of the gap.
    shares : dict of str to float
        Share of the gap's samples per reason (sums to 1).
    occlusions : tuple of Occlusion
        One per occluded sample and camera that had the target in view (nearest blocker).
    """

    t_start_s: float
    t_end_s: float
    reason: str
    shares: dict[str, float] = field(default_factory=dict)
    occlusions: tuple[Occlusion, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (occlusions summarised by sensor and kind, first of each)."""
        first: dict[tuple[str, str], Occlusion] = {}
        for o in self.occlusions:
            first.setdefault((o.sensor, o.kind), o)
        return {
            "t_start_s": self.t_start_s,
            "t_end_s": self.t_end_s,
            "reason": self.reason,
            "shares": {k: round(v, 3) for k, v in self.shares.items()},
            "blockers": [o.to_dict() for o in first.values()],
        }


def _local_ground(dem: Dem, p: np.ndarray, window_m: float) -> float:
    """Lowest DEM elevation within ``window_m`` of ``p`` (a bare-earth estimate, m)."""
    g = dem.grid
    r, c = g.cell_of(np.array([p[0]]), np.array([p[1]]))
    k = max(1, int(round(window_m / g.cell_m)))
    r0, c0 = max(int(r[0]) - k, 0), max(int(c[0]) - k, 0)
    patch = dem.elevation[r0 : int(r[0]) + k + 1, c0 : int(c[0]) + k + 1]
    return float(np.nanmin(patch)) if patch.size and np.isfinite(patch).any() else float(p[2])


def explain_gap(
    dem: Dem,
    cameras: Mapping[str, Camera],
    path: Callable[[np.ndarray], np.ndarray],
    t_start_s: float,
    t_end_s: float,
    *,
    height_m: float = 1.5,
    dt_s: float = 0.5,
    min_fraction: float = 0.3,
    max_range_m: float = 1000.0,
    object_min_m: float = 2.0,
    ground_window_m: float = 15.0,
) -> GapExplanation:
    """Explain one gap; see the module docstring.

    Parameters
    ----------
    dem : Dem
        First-return surface (roofs and crowns occlude).
    cameras : mapping of str to Camera
        The cameras as they pointed during the gap.
    path : callable
        ``path(t_s)`` -> foot positions ``(n, 3)`` in the site frame (m) for times ``(n,)``.
    t_start_s, t_end_s : float
        The gap (s); samples are taken strictly inside it (at least one).
    height_m : float
        Target height (1.5 m for a car, 1.7 m for a person).
    """
    if not t_end_s > t_start_s:
        raise TrackingError(f"gap must end after it starts, got {t_start_s}..{t_end_s}")
    n = max(1, int(np.floor((t_end_s - t_start_s) / dt_s)))
    t = t_start_s + (np.arange(n) + 0.5) * (t_end_s - t_start_s) / n
    feet = np.asarray(path(t), dtype=np.float64).reshape(n, 3)
    mid = feet + [0.0, 0.0, height_m / 2]
    in_view = np.zeros(n, bool)
    visible = np.zeros(n, bool)
    blocked: list[tuple[int, str, Camera]] = []
    for sid, cam in cameras.items():
        # In the image: the target's top, middle or foot projects onto it.
        sees = cam.in_view(mid) | cam.in_view(feet + [0.0, 0.0, height_m]) | cam.in_view(feet)
        frac = target_visible_fraction(
            dem, cam, feet, height_m, max_range_m=max_range_m, in_view=False
        )
        in_view |= sees
        ok = sees & (frac >= min_fraction)
        visible |= ok
        blocked += [(int(i), sid, cam) for i in np.flatnonzero(sees & ~ok)]
    label = np.where(~in_view, 0, np.where(visible, 2, 1))
    counts = np.bincount(label, minlength=3)
    shares = {r: float(counts[k]) / n for k, r in enumerate(REASONS)}
    reason = REASONS[int(np.argmax(counts))]
    occlusions = []
    for i, sid, cam in blocked:
        if label[i] != 1:
            continue
        c = np.asarray(cam.position_enu, dtype=np.float64)
        d = mid[i] - c
        hits = cast_rays(dem, c[None, :], d[None, :], float(np.linalg.norm(d)), mode="first")
        if hits.counts[0] == 0:
            continue  # blocked only below the middle: the lower part hides behind a low edge
        p = hits.first_points()[0]
        above = float(p[2] - _local_ground(dem, p, ground_window_m))
        kind = "object" if above > object_min_m else "terrain"
        occlusions.append(Occlusion(sid, float(t[i]), p, kind, above))
    return GapExplanation(float(t_start_s), float(t_end_s), reason, shares, tuple(occlusions))


def _linear_path(t_track: np.ndarray, p_track: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
    def path(t: np.ndarray) -> np.ndarray:
        return np.column_stack([np.interp(t, t_track, p_track[:, k]) for k in range(3)])

    return path


def explain_track_gaps(
    dem: Dem,
    cameras: Mapping[str, Camera],
    track: Any,
    *,
    path: Callable[[np.ndarray], np.ndarray] | None = None,
    height_m: float | None = None,
    **kwargs: Any,
) -> list[GapExplanation]:
    """Explain every gap of ``track`` (``t_s``, ``p_enu``, ``gaps``, ``cls``).

    ``path`` defaults to the straight line across each gap between the track's points;
    ``height_m`` to 1.5 m for vehicles and 1.7 m for people. Other keywords go to
    :func:`explain_gap`.
    """
    if height_m is None:
        height_m = target_height_for(getattr(track, "cls", None))
    if path is None:
        path = _linear_path(np.asarray(track.t_s, float), np.asarray(track.p_enu, float))
    return [
        explain_gap(dem, cameras, path, a, b, height_m=height_m, **kwargs)
        for a, b in track.gaps
        if b > a
    ]
