"""Fix bodies <-> tracker fixes: the one way a stored fix becomes the tracker's input.

A fix's stored body (the ``fixes`` table, the ``fix`` stream message) is made here from
the builder's :class:`~demtrack.core.tracking.types.Fix`. The start-up replay makes the
tracker's fix back from that body by :func:`fixes_from_bodies`, through the one
validating, vectorised constructor
:meth:`Fix.from_arrays <demtrack.core.tracking.types.Fix.from_arrays>`; the live run
makes the same fix from the builder's own (:func:`tracker_fixes`, with
:meth:`Fix.reindexed <demtrack.core.tracking.types.Fix.reindexed>`: the same arithmetic,
without going through lists). The body holds the fix's own floats (``tolist`` and JSON
keep every bit), so a restart hands the tracker the very fixes the live run did:
identical tracks (the oracle test compares the two fixes bit for bit).

Body hits hold their geodetic fields (``lat_deg``, ``lon_deg``, ``h_m``) in place but
None when made: the pipeline fills them from the batch's one geodetic conversion.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from demtrack.core.tracking.types import Detection, Fix

__all__ = ["fix_bodies", "fix_from_body", "fixes_from_bodies", "hit_body", "tracker_fixes"]

#: Placeholders for rows :meth:`Fix.from_arrays` does not read (no road point, no covariance).
_NO_ROAD = [0.0, 0.0, 0.0]
_NO_COV = [[1.0, 0.0], [0.0, 1.0]]


def hit_body(p: list[float], sigma: float, cov: list[list[float]] | None = None) -> dict[str, Any]:
    """A stored hit; its geodetic fields (None here, in their places) are filled later."""
    hit: dict[str, Any] = {
        "e_m": p[0],
        "n_m": p[1],
        "u_m": p[2],
        "lat_deg": None,
        "lon_deg": None,
        "h_m": None,
        "sigma_m": sigma,
    }
    if cov is not None:
        hit["cov_en_m2"] = cov
    return hit


def fix_bodies(
    pending: Sequence[tuple[int, Detection]], fixes: Sequence[Fix]
) -> tuple[list[dict[str, Any] | None], list[tuple[np.ndarray, list[dict[str, Any]]]]]:
    """The stored body of each detection's fix (None: no fix), geodetic fields unfilled.

    ``fixes``: :func:`~demtrack.core.geolocation.fix_builder.build_fixes` of the
    detections of ``pending`` (``detection_index`` = position in ``pending``, increasing).
    The second value, ``[(points (k, 3), dicts)]`` (the hits, then the road points if any;
    empty when there is no fix), is what fills the hits' and road points' ``lat_deg``,
    ``lon_deg`` and ``h_m`` before the bodies are used.
    Every fix's floats reach the bodies through one ``tolist`` per array kind.
    """
    out: list[dict[str, Any] | None] = [None] * len(pending)
    if not fixes:
        return out, []
    points = np.concatenate([f.hits_enu for f in fixes])
    rows = points.tolist()
    sigmas = np.concatenate([f.hit_sigma_m for f in fixes]).tolist()
    with_cov = all(f.hit_cov_en_m2 is not None for f in fixes)
    covs = np.concatenate([f.hit_cov_en_m2 for f in fixes]).tolist() if with_cov else None
    origins = np.array([f.origin_enu for f in fixes]).tolist()
    directions = np.array([f.direction_enu for f in fixes]).tolist()
    hit_dicts: list[dict[str, Any]] = []
    road_points, road_dicts = [], []
    lo = 0
    for f, origin, direction in zip(fixes, origins, directions, strict=True):
        hi = lo + len(f.hit_sigma_m)
        if covs is not None:
            cov_f: list[Any] = covs[lo:hi]
        elif f.hit_cov_en_m2 is not None:
            cov_f = f.hit_cov_en_m2.tolist()
        else:
            cov_f = [None] * (hi - lo)
        hits = [
            hit_body(p, sigma, cov)
            for p, sigma, cov in zip(rows[lo:hi], sigmas[lo:hi], cov_f, strict=True)
        ]
        hit_dicts += hits
        road = None
        if f.road_hit_enu is not None:
            road = hit_body(f.road_hit_enu.tolist(), min(sigmas[lo:hi], default=1.0))
            road_points.append(f.road_hit_enu)
            road_dicts.append(road)
        lo = hi
        det_id, d = pending[f.detection_index]
        u0, _, u1, v1 = d.bbox
        out[f.detection_index] = {
            "detection_id": det_id,
            "t_s": d.t_s,
            "sensor": d.sensor,
            "cls": d.cls,
            "score": d.score,
            "bbox": list(d.bbox),
            "foot_pixel": [0.5 * (u0 + u1), v1],
            "origin_enu": origin,
            "direction_enu": direction,
            "hits": hits,
            "road_hit": road,
            "tracked": True,
        }
    work = [(points, hit_dicts)]
    if road_points:
        work.append((np.array(road_points), road_dicts))
    return out, work


def tracker_fixes(
    bodies: Sequence[dict[str, Any] | None], fixes: Sequence[Fix]
) -> list[tuple[int, Fix]]:
    """``(detection id, the tracker's fix)`` of each body of :func:`fix_bodies`.

    The fix :func:`fixes_from_bodies` makes of the stored body, bit for bit (the start-up
    replay's fix), made from the builder's fix itself (:meth:`Fix.reindexed`) rather than
    from the body's lists: the body holds the builder's own floats.
    """
    out = []
    for f in fixes:
        body = bodies[f.detection_index]
        assert body is not None  # fix_bodies made one for every fix
        made = f.reindexed(body["detection_id"]) if f.n_hits else fix_from_body(body)
        out.append((body["detection_id"], made))
    return out


def fixes_from_bodies(bodies: Sequence[dict[str, Any]]) -> list[Fix]:
    """The tracker's :class:`Fix` of each stored fix body (``detection_index`` = detection id).

    One call of :meth:`Fix.from_arrays` for all of them: validated once over the stacked
    arrays, the direction normalised as the constructor does. A body stored before
    covariances were kept has none (the tracker uses ``sigma_m``). A malformed body raises
    the constructor's :class:`~demtrack.core.errors.TrackingError`, which names the problem.
    """
    t_s, sensor, cls, ids, score = [], [], [], [], []
    origin, direction, road, has_road, has_cov = [], [], [], [], []
    offsets, hits, sigma, cov = [0], [], [], []
    for b in bodies:
        t_s.append(b["t_s"])
        sensor.append(b["sensor"])
        cls.append(b["cls"])
        ids.append(b["detection_id"])
        score.append(b.get("score"))
        origin.append(b["origin_enu"])
        direction.append(b["direction_enu"])
        r = b.get("road_hit")
        road.append(_NO_ROAD if r is None else [r["e_m"], r["n_m"], r["u_m"]])
        has_road.append(r is not None)
        body_hits = b["hits"]
        covs = [h.get("cov_en_m2") for h in body_hits]
        with_cov = bool(covs) and all(c is not None for c in covs)
        has_cov.append(with_cov)
        for h, c in zip(body_hits, covs, strict=True):
            hits.append([h["e_m"], h["n_m"], h["u_m"]])
            sigma.append(h["sigma_m"])
            cov.append(c if with_cov else _NO_COV)
        offsets.append(len(sigma))
    return Fix.from_arrays(
        t_s,
        sensor,
        cls,
        ids,
        origin,
        direction,
        offsets,
        hits,
        sigma,
        road_hit_enu=road,
        has_road=has_road,
        score=score,
        hit_cov_en_m2=cov if any(has_cov) else None,
        has_cov=has_cov,
    )


def fix_from_body(body: dict[str, Any]) -> Fix:
    """The tracker's :class:`Fix` of one stored fix body (see :func:`fixes_from_bodies`)."""
    return fixes_from_bodies([body])[0]
