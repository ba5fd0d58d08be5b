"""Sensor hand-off: when a target leaves its camera, and which camera takes it next.

The paper's geospatial frame lets one camera's target be handed to another. For a target
at ``p_enu`` moving with ``v_enu``, :func:`predict_handoff` extrapolates its ground path
(constant velocity, on the DEM), asks each camera how much of the standing target it would
see at each future instant (:func:`~demtrack.core.visibility.viewshed.target_visible_fraction`), and
reports when the current camera loses it and which camera sees it next: one that already
points there, or else a pan-tilt head with a clear line of sight, with the pan and tilt it
should slew to so the target is centred.

:func:`evaluate_handoffs` scores the predictions on ground-truth paths: how often the named
next camera was the one that really saw the target next, and how early that was known.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..camera.pantilt import wrap_deg
from ..geolocation.roads import RoadNetwork
from ..site.folder import Sensor
from ..terrain.dem import Dem
from ..tracking.roadfollow import follow_road
from ..tracking.types import TruthPath
from .viewshed import target_visible_fraction

__all__ = [
    "HandoffPrediction",
    "HandoffScore",
    "HandoffTarget",
    "evaluate_handoffs",
    "predict_handoff",
    "predict_handoffs",
    "visibility_timeline",
]


@dataclass(frozen=True)
class HandoffPrediction:
    """What to expect for one target.

    Attributes
    ----------
    current : str or None
        The camera that sees the target now (None if none does).
    exit_in_s : float or None
        Seconds until the current camera loses it (None: not within the horizon).
    next_sensor : str or None
        The camera expected to see it next (None: none within the horizon).
    next_in_s : float or None
        Seconds until that camera sees it.
    slew : bool
        The next camera must turn to see it (it has a clear line of sight, but the target
        will not be in its current field of view).
    pan_deg, tilt_deg : float or None
        Where to point the next camera's head to centre the target at acquisition.
    acquisition_enu : ndarray, shape (3,), or None
        Predicted ground position at acquisition.
    """

    current: str | None
    exit_in_s: float | None
    next_sensor: str | None
    next_in_s: float | None
    slew: bool = False
    pan_deg: float | None = None
    tilt_deg: float | None = None
    acquisition_enu: np.ndarray | None = None


def _along_road(
    roads: RoadNetwork, p: np.ndarray, v: np.ndarray, times: np.ndarray, snap_m: float
) -> np.ndarray | None:
    """Future ground positions following the nearest road, or None if off the roads."""
    return follow_road(roads.lines, p, v, times, snap_m)


def _path(
    dem: Dem,
    p_enu: np.ndarray,
    v_enu: np.ndarray,
    times: np.ndarray,
    roads: RoadNetwork | None = None,
    snap_m: float = 5.0,
) -> np.ndarray:
    p, v = np.asarray(p_enu, float), np.asarray(v_enu, float)
    xy = _along_road(roads, p, v, times, snap_m) if roads is not None and len(roads) else None
    if xy is None:
        xy = p[None, :2] + times[:, None] * v[None, :2]
    z = dem.sample(xy[:, 0], xy[:, 1])
    return np.column_stack([xy, np.nan_to_num(z, nan=float(p[2]))])


def visibility_timeline(
    dem: Dem,
    sensors: Mapping[str, Sensor],
    points_enu: np.ndarray,
    height_m: float,
    *,
    in_view: bool = True,
    max_range_m: float = 1000.0,
) -> dict[str, np.ndarray]:
    """Visible fraction of the standing target at each point, per sensor."""
    return {
        sid: target_visible_fraction(
            dem, s.camera, points_enu, height_m, max_range_m=max_range_m, in_view=in_view
        )
        for sid, s in sensors.items()
    }


def _first(flags: np.ndarray) -> int | None:
    idx = np.flatnonzero(flags)
    return int(idx[0]) if len(idx) else None


def predict_handoff(
    dem: Dem,
    sensors: Mapping[str, Sensor],
    p_enu: np.ndarray,
    v_enu: np.ndarray,
    *,
    current: str | None = None,
    height_m: float = 1.5,
    horizon_s: float = 20.0,
    dt_s: float = 0.5,
    min_fraction: float = 0.5,
    max_range_m: float = 1000.0,
    roads: RoadNetwork | None = None,
) -> HandoffPrediction:
    """Predict the hand-off of a target at ``p_enu`` moving at ``v_enu`` (m, m/s).

    ``current`` defaults to the camera that sees most of the target now. A camera "sees"
    the target when at least ``min_fraction`` of its height is visible. With ``roads``, a
    target within 5 m of a road is extrapolated along it (a vehicle follows the road),
    keeping its lateral offset; otherwise in a straight line.
    """
    target = HandoffTarget(p_enu, v_enu, current, height_m, roads)
    return predict_handoffs(
        dem,
        sensors,
        [target],
        horizon_s=horizon_s,
        dt_s=dt_s,
        min_fraction=min_fraction,
        max_range_m=max_range_m,
    )[0]


@dataclass(frozen=True, eq=False)
class HandoffTarget:
    """One target for :func:`predict_handoffs`: the arguments of :func:`predict_handoff`."""

    p_enu: np.ndarray
    v_enu: np.ndarray
    current: str | None = None
    height_m: float = 1.5
    roads: RoadNetwork | None = None


def predict_handoffs(
    dem: Dem,
    sensors: Mapping[str, Sensor],
    targets: Sequence[HandoffTarget],
    *,
    horizon_s: float = 20.0,
    dt_s: float = 0.5,
    min_fraction: float = 0.5,
    max_range_m: float = 1000.0,
) -> list[HandoffPrediction]:
    """:func:`predict_handoff` for many targets at once: the same predictions.

    Every target's future path is checked against each camera in one visibility call per
    camera and target height (not one per target and camera): the per-point answers are
    the same, the fixed cost of a call is paid a few times instead of once per target.
    """
    times = np.arange(0.0, horizon_s + 1e-9, dt_s)
    paths = [_path(dem, t.p_enu, t.v_enu, times, t.roads) for t in targets]
    fractions: list[dict[str, np.ndarray]] = [{} for _ in targets]
    for height in sorted({float(t.height_m) for t in targets}):
        which = [i for i, t in enumerate(targets) if float(t.height_m) == height]
        stacked = np.concatenate([paths[i] for i in which])
        for sid, frac in visibility_timeline(
            dem, sensors, stacked, height, max_range_m=max_range_m
        ).items():
            for k, i in enumerate(which):
                fractions[i][sid] = frac[k * len(times) : (k + 1) * len(times)]
    return [
        _decide(dem, sensors, t, path, times, frac, min_fraction, max_range_m)
        for t, path, frac in zip(targets, paths, fractions, strict=True)
    ]


def _decide(
    dem: Dem,
    sensors: Mapping[str, Sensor],
    target: HandoffTarget,
    path: np.ndarray,
    times: np.ndarray,
    fractions: Mapping[str, np.ndarray],
    min_fraction: float,
    max_range_m: float,
) -> HandoffPrediction:
    """One target's prediction from its path and each camera's visible fractions on it."""
    height_m = target.height_m
    seen = {sid: f >= min_fraction for sid, f in fractions.items()}
    current = target.current
    if current is None:
        now = {sid: f[0] for sid, f in seen.items() if f[0]}
        current = next(iter(now), None)
    exit_idx = _first(~seen[current]) if current is not None else 0
    exit_in = None if exit_idx is None else float(times[exit_idx])
    start = exit_idx if exit_idx is not None else len(times)
    # A camera already pointing there, soonest first.
    best: tuple[int, str] | None = None
    for sid, flags in seen.items():
        if sid == current:
            continue
        k = _first(flags[start:]) if start < len(times) else None
        if k is not None and (best is None or start + k < best[0]):
            best = (start + k, sid)
    if best is not None:
        k, sid = best
        return HandoffPrediction(current, exit_in, sid, float(times[k]), False, None, None, path[k])
    if exit_idx is None:
        return HandoffPrediction(current, None, None, None)
    # Nobody points there: the pan-tilt head with a clear sight line soonest, slewed.
    others = {sid: s for sid, s in sensors.items() if sid != current}
    clear = visibility_timeline(
        dem, others, path[start:], height_m, in_view=False, max_range_m=max_range_m
    )
    for k in range(len(times) - start):
        for sid, frac in clear.items():
            if frac[k] >= min_fraction:
                s = sensors[sid]
                aim = path[start + k] + [0.0, 0.0, height_m / 2]
                d = aim - s.head.position_enu
                az = float(np.degrees(np.arctan2(d[0], d[1])))
                tilt = float(np.degrees(np.arctan2(d[2], np.hypot(d[0], d[1]))))
                pan = float(wrap_deg(az - s.head.mount_yaw_deg))
                return HandoffPrediction(
                    current, exit_in, sid, float(times[start + k]), True, pan, tilt, path[start + k]
                )
    return HandoffPrediction(current, exit_in, None, None)


@dataclass(frozen=True)
class HandoffScore:
    """Hand-off predictions against what really happened on ground-truth paths.

    Attributes
    ----------
    handoffs : int
        Times a target left a camera's view and another camera saw it later.
    correct : int
        Of those, how many the prediction made ``lead_s`` before the exit named right.
    lead_s : float
        How long before the real exit the predictions were made (at most: see ``leads_s``).
    early_s : tuple of float
        For each hand-off predicted right at some time, how long before the exit the
        prediction first named the right camera (within the horizon).
    leads_s : tuple of float
        For each hand-off, how long before the exit its scored prediction was made:
        ``lead_s``, or less when the current camera took the target over later than that
        (it cannot predict before it holds the target).
    """

    handoffs: int
    correct: int
    lead_s: float
    early_s: tuple[float, ...]
    leads_s: tuple[float, ...] = ()

    @property
    def accuracy(self) -> float:
        """Share of hand-offs predicted right (NaN when there were none)."""
        return self.correct / self.handoffs if self.handoffs else float("nan")


def evaluate_handoffs(
    dem: Dem,
    sensors: Mapping[str, Sensor],
    truths: Sequence[TruthPath],
    *,
    height_m: float = 1.5,
    lead_s: float = 2.0,
    dt_s: float = 0.5,
    horizon_s: float = 20.0,
    min_fraction: float = 0.5,
    roads: RoadNetwork | None = None,
) -> HandoffScore:
    """Score :func:`predict_handoff` on ground-truth paths.

    The truth is resampled every ``dt_s``. The camera holding the target keeps it while it
    sees at least ``min_fraction`` of it; when it loses it, the camera that sees most of it
    then (or first afterwards) takes over. At each such hand-off, the prediction made
    ``lead_s`` before it (with the truth's velocity, and ``roads`` if given) - or, when the
    current camera took the target over less than ``lead_s`` before, the first one it could
    make - is compared with the camera that really took the target.
    """
    handoffs = correct = 0
    early: list[float] = []
    leads: list[float] = []
    for truth in truths:
        t = np.arange(truth.t_s[0], truth.t_s[-1], dt_s)
        p = truth.at(t)
        v = np.gradient(p, dt_s, axis=0)
        frac = visibility_timeline(dem, sensors, p, height_m)
        ids = list(frac)
        seen = np.column_stack([frac[s] >= min_fraction for s in ids])
        share = np.column_stack([frac[s] for s in ids])
        current = int(np.argmax(share[0])) if seen[0].any() else -1
        for i in range(1, len(t)):
            if current < 0:
                current = int(np.argmax(share[i])) if seen[i].any() else -1
                continue
            if seen[i, current]:
                continue
            # The current camera lost the target at t[i]: who sees it next?
            others = np.flatnonzero(seen[i])
            later = np.flatnonzero(seen[i:].any(axis=1))
            if len(others):
                nxt = int(others[np.argmax(share[i, others])])
            elif len(later):
                j = i + int(later[0])
                nxt = int(np.argmax(share[j]))
            else:
                break
            if nxt == current:
                continue  # lost and found again by the same camera: a gap, not a hand-off
            handoffs += 1
            # The prediction is made lead_s before the exit, or as soon as the current
            # camera holds the target when it took it over less than lead_s before.
            held = i - 1
            while held > 0 and seen[held - 1, current]:
                held -= 1
            k_lead = max(held, i - int(round(lead_s / dt_s)))
            leads.append(float(t[i] - t[k_lead]))
            first_right = None
            for k in range(max(held, i - int(horizon_s / dt_s)), i):
                pred = predict_handoff(
                    dem, sensors, p[k], v[k], current=ids[current], height_m=height_m,
                    horizon_s=horizon_s, dt_s=dt_s, min_fraction=min_fraction, roads=roads,
                )  # fmt: skip
                right = pred.next_sensor == ids[nxt]
                if right and first_right is None:
                    first_right = t[i] - t[k]
                if right and k == k_lead:
                    correct += 1
            if first_right is not None:
                early.append(float(first_right))
            current = nxt if seen[i, nxt] else -1
    return HandoffScore(handoffs, correct, lead_s, tuple(early), tuple(leads))
