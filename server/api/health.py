"""``/api/health``: liveness (open) and ``/api/status``: progress (reader)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from ..models import HealthOut
from .deps import READER, StateDep
from .errors import error_responses

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["health"])


@router.get("/health", response_model=HealthOut, summary="Liveness")
async def health(request: Request) -> dict[str, Any]:
    """``ok`` once the site is loaded, the store open and the tracker rebuilt.

    Answered on the event loop from memory (the schema version read at start-up, the
    hub's newest sequence number): it never waits for a worker thread or the database,
    so it answers while expensive reads queue. (No ``StateDep``: FastAPI runs a plain
    ``def`` dependency in the worker threads too.)
    """
    state = request.app.state.console
    return {
        "status": "ok",
        "schema_version": request.app.state.schema_version,
        "last_seq": state.hub.last_seq,
        "viser_url": getattr(request.app.state, "viser_url", None),
    }


@router.get(
    "/status",
    response_model=HealthOut,
    dependencies=READER,
    responses=error_responses(401),
    summary="Progress",
)
def status(state: StateDep) -> dict[str, Any]:
    """Row counts and stream state."""
    counts = state.store.counts()
    counts["ws_clients"] = len(state.hub.clients)
    counts["ws_dropped"] = state.hub.n_dropped
    counts["late_fixes"] = state.pipeline.n_late
    counts["no_pose"] = state.pipeline.pose_book.n_no_pose  # never geolocated: no pose near
    counts["poses_stored"] = state.pipeline.pose_book.n_stored
    counts["pose_waiting"] = len(state.pipeline.pose_book.waiting)
    counts["ingest_commits"] = state.pipeline.n_commits  # group commit: batches per commit
    counts["ingest_batches"] = state.pipeline.n_batches
    return {
        "status": "ok",
        "schema_version": state.store.schema_version(),
        "last_seq": state.store.last_seq(),
        "counts": counts,
    }
