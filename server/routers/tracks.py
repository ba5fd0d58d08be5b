"""``/api/tracks``: the tracker's tracks with time-window, class, sensor and box filters."""

from __future__ import annotations

from typing import Any, Literal

from fastapi import APIRouter, HTTPException, Query

from ..models import TracksOut
from ..state import StateDep

__all__ = ["parse_bbox", "router"]

router = APIRouter(prefix="/api/tracks", tags=["tracks"])


def parse_bbox(text: str | None) -> tuple[float, float, float, float] | None:
    """``"e_min,n_min,e_max,n_max"`` (site frame, m) -> tuple; HTTP 422 if malformed."""
    if text is None:
        return None
    try:
        box = tuple(float(x) for x in text.split(","))
    except ValueError:
        box = ()
    if len(box) != 4 or not all(abs(x) < 1e12 for x in box) or box[0] > box[2] or box[1] > box[3]:
        raise HTTPException(
            422, f"bbox must be 'e_min,n_min,e_max,n_max' (m, min <= max), got {text!r}"
        )
    return box  # type: ignore[return-value]


def _clip(track: dict[str, Any], t_from: float | None, t_to: float | None) -> dict[str, Any]:
    pts = [
        p
        for p in track["points"]
        if (t_from is None or p["t_s"] >= t_from) and (t_to is None or p["t_s"] <= t_to)
    ]
    first = track["points"].index(pts[0]) if pts else 0
    return dict(track, points=pts, first_index=first)


def _in_box(track: dict[str, Any], box: tuple[float, float, float, float]) -> bool:
    return any(
        box[0] <= p["e_m"] <= box[2] and box[1] <= p["n_m"] <= box[3] for p in track["points"]
    )


@router.get("", response_model=TracksOut, summary="Tracks")
def list_tracks(
    state: StateDep,
    t_from: float | None = Query(None, description="window start (s)", allow_inf_nan=False),
    t_to: float | None = Query(None, description="window end (s)", allow_inf_nan=False),
    cls: Literal["vehicle", "human"] | None = Query(None, alias="class"),
    sensor: str | None = Query(None, max_length=200, description="seen by this sensor"),
    bbox: str | None = Query(None, description="e_min,n_min,e_max,n_max (site frame, m)"),
) -> dict[str, Any]:
    """Tracks matching every filter given.

    A track is listed when it has a point in the time window (its points are clipped to
    it), is of the class, was seen by the sensor, and passes through the box.
    """
    if t_from is not None and t_to is not None and t_from > t_to:
        raise HTTPException(422, f"t_from ({t_from}) is after t_to ({t_to})")
    box = parse_bbox(bbox)
    out = []
    for body in state.store.tracks(t_from=t_from, t_to=t_to, cls=cls, bbox=box):
        if sensor is not None and sensor not in body["sensors"]:
            continue
        clipped = _clip(body, t_from, t_to)
        if not clipped["points"] or (box is not None and not _in_box(clipped, box)):
            continue
        out.append(clipped)
    return {"tracks": out}


@router.get("/{track_id}", response_model=TracksOut, summary="One track")
def get_track(track_id: int, state: StateDep) -> dict[str, Any]:
    """One track with all its points."""
    found = [b for b in state.store.tracks() if b["id"] == track_id]
    if not found:
        raise HTTPException(404, f"no track {track_id}")
    return {"tracks": found}
