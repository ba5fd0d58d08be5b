"""``/api/scene3d/follow``: which track the 3D scene's cameras follow.

The console sends ``PUT`` when the operator selects a track (and ``track_id: null`` when
the selection is cleared); the viser scene then points every connected client's camera
at the track's newest position and keeps following it (:meth:`Scene3D.follow`). The
choice is the scene's, so every 3D client follows the same track.
"""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Depends, HTTPException, Request
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool

from ..security import require_operator, require_reader
from ..state import StateDep

__all__ = ["FollowIn", "FollowOut", "router"]

router = APIRouter(prefix="/api/scene3d", tags=["scene3d"])


class FollowIn(BaseModel):
    """The track to follow, or null to stop."""

    model_config = ConfigDict(extra="forbid")

    track_id: int | None = Field(..., ge=0, description="track id; null stops following")


class ClientCamera(BaseModel):
    """A connected 3D client's camera (site frame, m)."""

    id: int
    look_at_enu: tuple[float, float, float]
    position_enu: tuple[float, float, float]


class FollowOut(BaseModel):
    """What the 3D scene follows and where its clients look."""

    track_id: int | None
    look_at_enu: tuple[float, float, float] | None = Field(
        description="the followed track's newest point (site frame, m), lifted 0.4 m as drawn"
    )
    clients: list[ClientCamera]


def _scene(request: Request) -> Any:
    scene = getattr(request.app.state, "scene3d", None)
    if scene is None:
        raise HTTPException(404, "the 3D scene is not running (start the server with --3d)")
    return scene


@router.get(
    "/follow",
    response_model=FollowOut,
    dependencies=[Depends(require_reader)],
    summary="The followed track and the 3D clients' cameras",
)
def get_follow(request: Request) -> dict[str, Any]:
    """The followed track (or null), its look-at point, and each connected client's camera."""
    state: dict[str, Any] = _scene(request).follow_state()
    return state


@router.put(
    "/follow",
    response_model=FollowOut,
    dependencies=[Depends(require_operator)],
    summary="Follow a track in the 3D scene",
)
async def put_follow(body: FollowIn, request: Request, state: StateDep) -> dict[str, Any]:
    """Point every 3D client's camera at the track's newest position and keep following it.

    404 for a track the server does not have. Answers once the scene has taken the
    request (or after 2 s), with the same body as ``GET``.
    """
    scene = _scene(request)
    track = None
    if body.track_id is not None:
        found = [b for b in state.store.tracks() if b["id"] == body.track_id]
        if not found:
            raise HTTPException(404, f"no track {body.track_id}")
        track = found[0]
    scene.follow(body.track_id, track)
    await run_in_threadpool(scene.flush, 2.0)
    out: dict[str, Any] = scene.follow_state()
    return out
