"""``/api/scene3d/follow``: which track the 3D scene's cameras follow.

The console sends ``PUT`` when the operator selects a track (and ``track_id: null`` when
the selection is cleared); the viser scene then points the cameras of that console page's
viser clients (its follow ``session``) at the track's newest position and keeps following
it (:meth:`Scene3D.follow`). Without a session the choice is the broadcast one: every 3D
client follows the same track (and the sessions' own choices are dropped).

``PUT /api/scene3d/session`` (operator token) admits a page's follow session into the
scene: the viser server closes every WebSocket whose path names no admitted session
before it sends anything (``server/scene3d/connections.py``), so the 3D view needs the
operator token as the console does. A ``PUT /follow`` with a session admits it too.
"""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Query, Request
from pydantic import BaseModel, ConfigDict, Field
from starlette.concurrency import run_in_threadpool

from demtrack.core.errors import NotFoundError

from ..scene3d import FOLLOW_PATH, SESSION_PATTERN
from ..track_query import stored_track
from .deps import OPERATOR, READER, StateDep

__all__ = ["FollowIn", "FollowOut", "SessionIn", "SessionOut", "router"]

router = APIRouter(prefix="/api/scene3d", tags=["scene3d"])


class FollowIn(BaseModel):
    """The track to follow, or null to stop."""

    model_config = ConfigDict(extra="forbid")

    track_id: int | None = Field(..., ge=0, description="track id; null stops following")
    session: str | None = Field(
        None,
        pattern=SESSION_PATTERN,
        description=(
            "follow session (a console page's random id): only the viser clients that"
            f" connected on `ws://<viser>{FOLLOW_PATH}<session>` move; omitted, every"
            " client follows and the sessions' own choices are dropped"
        ),
    )


class ClientCamera(BaseModel):
    """A connected 3D client's camera (site frame, m)."""

    id: int
    session: str | None = Field(None, description="the follow session it joined, if any")
    track_id: int | None = Field(None, description="the track its camera follows, if any")
    look_at_enu: tuple[float, float, float]
    position_enu: tuple[float, float, float]


class FollowOut(BaseModel):
    """What the 3D scene follows and where its clients look."""

    track_id: int | None
    look_at_enu: tuple[float, float, float] | None = Field(
        description="the followed track's newest point (site frame, m), lifted 0.4 m as drawn"
    )
    clients: list[ClientCamera]


class SessionIn(BaseModel):
    """A console page's follow session, to admit into the 3D scene."""

    model_config = ConfigDict(extra="forbid")

    session: str = Field(
        ...,
        pattern=SESSION_PATTERN,
        description=f"the page's random id; its viser client connects on `{FOLLOW_PATH}<session>`",
    )


class SessionOut(BaseModel):
    """The admitted session and where its viser client connects."""

    session: str
    websocket_path: str = Field(description="the WebSocket path the viser client must use")


SessionQuery = Annotated[
    str | None,
    Query(pattern=SESSION_PATTERN, description="a follow session (see PUT); omitted: all"),
]


def _scene(request: Request) -> Any:
    scene = getattr(request.app.state, "scene3d", None)
    if scene is None:
        raise NotFoundError("the 3D scene is not running (start the server with --3d)")
    return scene


@router.put(
    "/session",
    response_model=SessionOut,
    dependencies=OPERATOR,
    summary="Admit a console page's viser client into the 3D scene",
)
def put_session(body: SessionIn, request: Request) -> dict[str, Any]:
    """Let the viser clients that connect on ``/follow/<session>`` see the scene.

    Without it the scene closes their WebSocket (code 4401) before sending anything.
    """
    _scene(request).admit(body.session)
    return {"session": body.session, "websocket_path": f"{FOLLOW_PATH}{body.session}"}


@router.get(
    "/follow",
    response_model=FollowOut,
    dependencies=READER,
    summary="The followed track and the 3D clients' cameras",
)
def get_follow(request: Request, session: SessionQuery = None) -> dict[str, Any]:
    """The followed track (or null), its look-at point, and the connected clients' cameras.

    With ``session``: that session's choice (its own, else the broadcast one) and its
    clients only; without: the broadcast choice and every client.
    """
    state: dict[str, Any] = _scene(request).follow_state(session)
    return state


@router.put(
    "/follow",
    response_model=FollowOut,
    dependencies=OPERATOR,
    summary="Follow a track in the 3D scene",
)
async def put_follow(body: FollowIn, request: Request, state: StateDep) -> dict[str, Any]:
    """Point 3D clients' cameras at the track's newest position and keep following it.

    The clients of ``session`` only, or every client without one. 404 for a track the
    server does not have. Answers once the scene has taken the request (or after 2 s),
    with the same body as ``GET`` (for the same session).
    """
    scene = _scene(request)
    track = None if body.track_id is None else stored_track(state, body.track_id)
    if body.session is not None:
        scene.admit(body.session)
    scene.follow(body.track_id, track, session=body.session)
    await run_in_threadpool(scene.flush, 2.0)
    out: dict[str, Any] = scene.follow_state(body.session)
    return out
