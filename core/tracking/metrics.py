"""Tracking metrics against true paths: accuracy, jumps, identity, OSPA/GOSPA.

All distances are horizontal (x, y of the local frame, m): heights of a track come from
terrain hits and say nothing about whether the right object was followed.

- Each track is assigned to the true target (same class) its points are closest to
  (median distance, at most ``match_threshold_m``); several tracks may share a target
  (fragmentation), a track near none is a false track.
- ``rmse_m`` / ``p95_m``: over every point of an assigned track, against its target's true
  position at the point's time.
- ``n_jumps``: those points more than ``jump_threshold_m`` off.
- ``id_switches`` / ``fragmentation``: at evaluation times (every ``dt_eval_s``), tracks
  present then are matched to targets by optimal assignment within ``match_threshold_m``;
  a switch is a target's matched track id changing (MOT-style, an unmatched spell in
  between does not reset it); fragmentation is the number of distinct tracks matched per
  target minus one, summed.
- ``ospa_m`` / ``gospa_m``: at the same times, between the true positions and the present
  tracks' positions, averaged.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from .ospa import gospa, ospa
from .types import Fix, Track, TruthPath

__all__ = [
    "TrackingMetrics",
    "count_fix_jumps",
    "evaluate",
    "match_tracks",
    "track_position_at",
]


@dataclass(frozen=True)
class TrackingMetrics:
    """Summary of a tracker's output against the truth.

    Parameters
    ----------
    rmse_m, p95_m : float
        Horizontal RMSE and 95th percentile error of assigned track points (m; NaN if none).
    n_points : int
        Assigned track points with a true position.
    n_jumps : int
        Of those, points off by more than the jump threshold.
    id_switches : int
        Identity switches.
    fragmentation : int
        Tracks per target minus one, summed over targets.
    n_tracks, n_false_tracks : int
        Tracks, and tracks assigned to no target.
    coverage : float
        Fraction of (target, evaluation time) pairs with a matched track.
    ospa_m, gospa_m : float
        Mean OSPA and GOSPA distances (m).
    """

    rmse_m: float
    p95_m: float
    n_points: int
    n_jumps: int
    id_switches: int
    fragmentation: int
    n_tracks: int
    n_false_tracks: int
    coverage: float
    ospa_m: float
    gospa_m: float


def _last_per_time(track: Track) -> tuple[np.ndarray, np.ndarray]:
    """Return times (increasing) and xy of a track, keeping the last point of equal times."""
    t = track.t_s
    xy = track.p_enu[:, :2]
    if t.size == 0:
        return t, xy
    keep = np.append(np.diff(t) > 0, True)
    return t[keep], xy[keep]


def track_position_at(track: Track, t_s: float) -> np.ndarray | None:
    """Horizontal position (2,) of ``track`` at ``t_s``; None outside it or in a gap."""
    t, xy = _last_per_time(track)
    if t.size == 0 or t_s < t[0] or t_s > t[-1]:
        return None
    if any(a < t_s < b for a, b in track.gaps):
        return None
    return np.array([np.interp(t_s, t, xy[:, 0]), np.interp(t_s, t, xy[:, 1])])


def _errors(track: Track, truth: TruthPath) -> np.ndarray:
    """Horizontal error of each point of ``track`` against ``truth`` (NaN where undefined)."""
    true = truth.at(track.t_s)[:, :2]
    return np.linalg.norm(track.p_enu[:, :2] - true, axis=1)


def match_tracks(
    tracks: Sequence[Track], truths: Sequence[TruthPath], match_threshold_m: float = 5.0
) -> dict[int, int | None]:
    """Track id -> target id of the same class with the smallest median error (or None)."""
    out: dict[int, int | None] = {}
    for track in tracks:
        best, best_err = None, np.inf
        for truth in truths:
            if truth.cls != track.cls:
                continue
            err = _errors(track, truth)
            err = err[np.isfinite(err)]
            if err.size and float(np.median(err)) < best_err:
                best, best_err = truth.target_id, float(np.median(err))
        out[track.id] = best if best_err <= match_threshold_m else None
    return out


def count_fix_jumps(
    fixes: Sequence[Fix],
    truths: Sequence[TruthPath],
    *,
    hit: str = "first",
    threshold_m: float = 3.0,
) -> int:
    """Count raw fixes off the true paths.

    A fix counts when its ``hit`` ("first" or "last") is farther than ``threshold_m``
    from every same-class target's true position at the fix time (fixes without hits
    are skipped).
    """
    k = 0 if hit == "first" else -1
    n = 0
    for fix in fixes:
        if fix.n_hits == 0:
            continue
        p = fix.hits_enu[k, :2]
        d = [
            float(np.linalg.norm(truth.at(fix.t_s)[0, :2] - p))
            for truth in truths
            if truth.cls == fix.cls
        ]
        d = [x for x in d if np.isfinite(x)]
        if not d or min(d) > threshold_m:
            n += 1
    return n


def evaluate(
    tracks: Sequence[Track],
    truths: Sequence[TruthPath],
    *,
    jump_threshold_m: float = 3.0,
    match_threshold_m: float = 5.0,
    ospa_c_m: float = 10.0,
    ospa_p: float = 2.0,
    dt_eval_s: float = 0.2,
) -> TrackingMetrics:
    """All metrics of ``tracks`` against ``truths`` (see the module docstring)."""
    assignment = match_tracks(tracks, truths, match_threshold_m)
    by_id = {t.target_id: t for t in truths}
    errors = []
    for track in tracks:
        target = assignment[track.id]
        if target is not None:
            err = _errors(track, by_id[target])
            errors.append(err[np.isfinite(err)])
    err = np.concatenate(errors) if errors else np.zeros(0)
    rmse = float(np.sqrt(np.mean(err**2))) if err.size else float("nan")
    p95 = float(np.percentile(err, 95)) if err.size else float("nan")

    t0 = min(float(t.t_s[0]) for t in truths)
    t1 = max(float(t.t_s[-1]) for t in truths)
    times = t0 + np.arange(0.0, t1 - t0 + 1e-9, dt_eval_s)  # relative: exact at UNIX times
    last_id: dict[int, int] = {}
    seen: dict[int, set[int]] = {t.target_id: set() for t in truths}
    switches = 0
    matched = 0
    possible = 0
    ospas, gospas = [], []
    for t in times:
        alive = [tr for tr in truths if tr.t_s[0] <= t <= tr.t_s[-1]]
        true_xy = np.array([tr.at(t)[0, :2] for tr in alive]).reshape(-1, 2)
        present = []
        for track in tracks:
            p = track_position_at(track, float(t))
            if p is not None:
                present.append((track, p))
        est_xy = np.array([p for _, p in present]).reshape(-1, 2)
        ospas.append(ospa(true_xy, est_xy, ospa_c_m, ospa_p))
        gospas.append(gospa(true_xy, est_xy, ospa_c_m, ospa_p).distance)
        possible += len(alive)
        if not alive or not present:
            continue
        d = np.linalg.norm(true_xy[:, None, :] - est_xy[None, :, :], axis=2)
        cls_ok = np.array([[tr.cls == tk.cls for tk, _ in present] for tr in alive])
        cost = np.where(cls_ok & (d <= match_threshold_m), d, 1e9)
        for r, c in zip(*linear_sum_assignment(cost), strict=True):
            if cost[r, c] >= 1e9:
                continue
            target, track_id = alive[r].target_id, present[c][0].id
            matched += 1
            if target in last_id and last_id[target] != track_id:
                switches += 1
            last_id[target] = track_id
            seen[target].add(track_id)
    fragmentation = sum(max(len(ids) - 1, 0) for ids in seen.values())
    return TrackingMetrics(
        rmse_m=rmse,
        p95_m=p95,
        n_points=int(err.size),
        n_jumps=int(np.sum(err > jump_threshold_m)),
        id_switches=switches,
        fragmentation=fragmentation,
        n_tracks=len(tracks),
        n_false_tracks=sum(1 for v in assignment.values() if v is None),
        coverage=matched / possible if possible else float("nan"),
        ospa_m=float(np.mean(ospas)),
        gospa_m=float(np.mean(gospas)),
    )
