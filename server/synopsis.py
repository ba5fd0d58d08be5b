"""The activity synopsis of a time window (Collins et al. 1998, Fig. 8).

Each long-term trajectory of the window is split into *tracked* parts (runs of points
with no gap between them, with the sensors that saw each run and when) and *gap* parts
(the target was seen by no sensor for longer than the tracker's gap threshold: the
sensors before and after, the gap's duration, and whether it was a hand-off, i.e. other
sensors picked the target up), together with the events of the window.
"""

from __future__ import annotations

import math
from bisect import bisect_left, bisect_right
from functools import partial
from typing import Any

from .state import ConsoleState
from .track_cache import CachedTrack
from .track_query import check_window, select_tracks

__all__ = [
    "assemble",
    "cached_trajectory",
    "synopsis",
    "trajectory",
    "trajectory_reference",
    "window_synopsis",
]


#: Points this close (s) to a full step apart count as a step apart: camera clocks are
#: microseconds, and at UNIX times (1.8e9 s, float64 grain 2.4e-7 s) a difference of
#: exactly one step would otherwise fall either side of it by rounding.
STEP_TOL_S = 1e-6


def _point(p: dict[str, Any]) -> dict[str, float]:
    return {k: p[k] for k in ("t_s", "e_m", "n_m", "u_m", "lat_deg", "lon_deg", "h_m")}


def _length(points: list[dict[str, Any]]) -> float:
    return float(
        sum(
            math.hypot(b["e_m"] - a["e_m"], b["n_m"] - a["n_m"])
            for a, b in zip(points, points[1:], strict=False)
        )
    )


def _in_gap(a: float, b: float, gaps: list[list[float]]) -> bool:
    return any(g0 <= a and b <= g1 for g0, g1 in gaps)


def _tracked(points: list[dict[str, Any]], step_s: float) -> dict[str, Any]:
    spans: dict[str, list[float]] = {}
    for p in points:
        for s in p["sensors"]:
            span = spans.setdefault(s, [p["t_s"], p["t_s"], 0])
            span[1] = p["t_s"]
            span[2] += 1
    path, last_t = [], -math.inf
    for k, p in enumerate(points):
        if p["t_s"] - last_t >= step_s - STEP_TOL_S or k == len(points) - 1:
            path.append(_point(p))
            last_t = p["t_s"]
    t0, t1 = points[0]["t_s"], points[-1]["t_s"]
    return {
        "kind": "tracked",
        "t_start_s": t0,
        "t_end_s": t1,
        "duration_s": t1 - t0,
        "sensors": sorted(spans),
        "sensor_spans": [
            {"sensor": s, "t_start_s": a, "t_end_s": b, "n_points": int(n)}
            for s, (a, b, n) in sorted(spans.items(), key=lambda kv: (kv[1][0], kv[0]))
        ],
        "n_points": len(points),
        "length_m": _length(points),
        "path": path,
    }


def _gap(a: dict[str, Any], b: dict[str, Any]) -> dict[str, Any]:
    before, after = sorted(a["sensors"]), sorted(b["sensors"])
    return {
        "kind": "gap",
        "t_start_s": a["t_s"],
        "t_end_s": b["t_s"],
        "duration_s": b["t_s"] - a["t_s"],
        "sensors_before": before,
        "sensors_after": after,
        "handoff": bool(set(after) - set(before)),
        "distance_m": math.hypot(b["e_m"] - a["e_m"], b["n_m"] - a["n_m"]),
        "start": _point(a),
        "end": _point(b),
    }


def _summary(
    body: dict[str, Any], pts: list[dict[str, Any]], parts: list[dict[str, Any]]
) -> dict[str, Any]:
    """A trajectory of ``body`` (clipped to ``pts``, time-ordered) made of ``parts``."""
    gaps = [p for p in parts if p["kind"] == "gap"]
    t0, t1 = pts[0]["t_s"], pts[-1]["t_s"]
    return {
        "track_id": body["id"],
        "cls": body["cls"],
        "live": body["live"],
        "t_start_s": t0,
        "t_end_s": t1,
        "duration_s": t1 - t0,
        "sensors": sorted({s for p in pts for s in p["sensors"]}),
        "n_points": len(pts),
        "length_m": sum(p["length_m"] for p in parts if p["kind"] == "tracked"),
        "n_gaps": len(gaps),
        "n_handoffs": sum(g["handoff"] for g in gaps),
        "parts": parts,
        "event_ids": [],
    }


def trajectory_reference(body: dict[str, Any], step_s: float) -> dict[str, Any]:
    """A (clipped) stored track body split into tracked parts and gaps (plain twin).

    Pair by pair and point by point: :func:`trajectory`'s reference in the tests, and
    what it falls back to when the points are not in time order.
    """
    pts = body["points"]
    parts: list[dict[str, Any]] = []
    run = [pts[0]]
    for a, b in zip(pts, pts[1:], strict=False):
        if _in_gap(a["t_s"], b["t_s"], body["gaps"]):
            parts.append(_tracked(run, step_s))
            parts.append(_gap(a, b))
            run = []
        run.append(b)
    parts.append(_tracked(run, step_s))
    return _summary(body, pts, parts)


def _since(t0: float, t: float) -> float:
    return t - t0


def _path(pts: list[dict[str, Any]], t_s: list[float], r0: int, r1: int, step_s: float) -> list:
    """``_tracked``'s path of ``pts[r0:r1]`` (times in order) by bisection.

    The next point kept is the first whose ``t_s - last >= step_s - STEP_TOL_S``: that difference
    never decreases along ordered times (rounding is monotonic), so it is bisected for.
    """
    path = [_point(pts[r0])]
    k = last = r0
    while True:
        k = bisect_left(t_s, step_s - STEP_TOL_S, k + 1, r1, key=partial(_since, t_s[last]))
        if k >= r1:
            break
        path.append(_point(pts[k]))
        last = k
    if last != r1 - 1:
        path.append(_point(pts[r1 - 1]))
    return path


def _skeleton(body: dict[str, Any], t_s: list[float]) -> dict[str, Any]:
    """:func:`trajectory` without paths (what does not depend on ``step_s``).

    Tracked parts carry ``"_run": (r0, r1)`` (their point range) in place of ``path``.
    ``t_s``: the times of ``body["points"]``, in order.
    """
    pts = body["points"]
    n = len(pts)
    # Pair (k, k + 1) lies in gap [g0, g1] iff t_s[k] >= g0 and t_s[k + 1] <= g1.
    cuts = sorted(
        {
            k
            for g0, g1 in body["gaps"]
            for k in range(bisect_left(t_s, g0), min(bisect_right(t_s, g1) - 1, n - 1))
        }
    )
    parts: list[dict[str, Any]] = []
    r0 = 0
    for k in cuts:
        parts.append({**_tracked(pts[r0 : k + 1], math.inf), "path": None, "_run": (r0, k + 1)})
        parts.append(_gap(pts[k], pts[k + 1]))
        r0 = k + 1
    parts.append({**_tracked(pts[r0:], math.inf), "path": None, "_run": (r0, n)})
    return _summary(body, pts, parts)


def _with_paths(
    skeleton: dict[str, Any], pts: list[dict[str, Any]], t_s: list[float], step_s: float
) -> dict[str, Any]:
    parts = []
    for part in skeleton["parts"]:
        if part["kind"] == "tracked":
            r0, r1 = part["_run"]
            part = {k: v for k, v in part.items() if k != "_run"}
            part["path"] = _path(pts, t_s, r0, r1, step_s)
        parts.append(part)
    return dict(skeleton, parts=parts, event_ids=[])


def _in_order(t_s: list[float]) -> bool:
    return all(a <= b for a, b in zip(t_s, t_s[1:], strict=False))


def trajectory(body: dict[str, Any], step_s: float) -> dict[str, Any]:
    """A (clipped) stored track body split into tracked parts and gaps.

    The same value as :func:`trajectory_reference`: gaps and path points are found by
    bisection over the (ordered) point times.
    """
    t_s = [p["t_s"] for p in body["points"]]
    if not _in_order(t_s):
        return trajectory_reference(body, step_s)
    return _with_paths(_skeleton(body, t_s), body["points"], t_s, step_s)


def cached_trajectory(track: CachedTrack, clipped: dict[str, Any], step_s: float) -> dict:
    """:func:`trajectory` of ``clipped`` (``track``'s body clipped), memoized on ``track``.

    Read-only: the value is shared by the requests that ask for the same window and
    ``step_s`` of the same stored version (:func:`synopsis` copies what it changes).
    """
    if not track.in_order:
        return trajectory_reference(clipped, step_s)
    i0 = clipped["first_index"]
    i1 = i0 + len(clipped["points"])
    t_s = track.t_s[i0:i1]
    skeleton = partial(_skeleton, clipped, t_s)
    skel = track.memoized(("synopsis-skeleton", i0, i1), skeleton)
    full = partial(_with_paths, skel, clipped["points"], t_s, step_s)
    return track.memoized(("synopsis", i0, i1, step_s), full)


def synopsis(
    bodies: list[dict[str, Any]],
    events: list[dict[str, Any]],
    t0: float | None,
    t1: float | None,
    step_s: float,
    filtered: bool,
) -> dict[str, Any]:
    """Assemble the synopsis from clipped track bodies and the window's events.

    With ``filtered`` (a class or sensor filter was given), only events that involve a
    listed trajectory are kept.
    """
    return assemble([trajectory(b, step_s) for b in bodies], events, t0, t1, filtered)


def assemble(
    trajectories: list[dict[str, Any]],
    events: list[dict[str, Any]],
    t0: float | None,
    t1: float | None,
    filtered: bool,
) -> dict[str, Any]:
    """The synopsis of computed trajectories (shared ones are copied, not changed)."""
    trajs = [dict(t, event_ids=[]) for t in trajectories]
    by_id = {t["track_id"]: t for t in trajs}
    kept = []
    for e in events:
        mine = [by_id[i] for i in e["track_ids"] if i in by_id]
        if filtered and not mine:
            continue
        kept.append(e)
        for t in mine:
            if e.get("id") is not None:
                t["event_ids"].append(e["id"])
    by_class: dict[str, int] = {}
    for t in trajs:
        by_class[t["cls"]] = by_class.get(t["cls"], 0) + 1
    kinds: dict[str, int] = {}
    for e in kept:
        kinds[e["kind"]] = kinds.get(e["kind"], 0) + 1
    return {
        "t0": t0,
        "t1": t1,
        "n_trajectories": len(trajs),
        "n_gaps": sum(t["n_gaps"] for t in trajs),
        "n_handoffs": sum(t["n_handoffs"] for t in trajs),
        "by_class": by_class,
        "events_by_kind": kinds,
        "trajectories": trajs,
        "events": kept,
    }


def window_synopsis(
    state: ConsoleState,
    t0: float | None,
    t1: float | None,
    cls: str | None,
    sensor: str | None,
    step_s: float,
) -> dict[str, Any]:
    """The synopsis ``GET /api/synopsis`` answers, with exactly ``SynopsisOut``'s keys.

    Tracks are selected as ``GET /api/tracks`` selects them (points clipped to the
    window); ``events`` are the stored events overlapping the window, only those
    involving a listed trajectory when a class or sensor filter is given.

    Raises
    ------
    QueryError
        ``t0`` after ``t1``.
    """
    check_window(t0, t1, first="t0", second="t1")
    trajs = [
        cached_trajectory(track, clipped, step_s)
        for track, clipped in select_tracks(state, t0, t1, cls, sensor, None)
    ]
    # EventBody's one default (stored bodies have their row id; older ones may not).
    events = [
        e if "id" in e else {"id": None, **e} for e in state.store.activity(t_from=t0, t_to=t1)
    ]
    return assemble(trajs, events, t0, t1, cls is not None or sensor is not None)
