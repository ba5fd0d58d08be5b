"""``/api/health``: liveness (open) and ``/api/status``: progress (reader)."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter, Request

from ..models import HealthOut
from .deps import READER, StateDep

__all__ = ["router"]

router = APIRouter(prefix="/api", tags=["health"])


@router.get("/health", response_model=HealthOut, summary="Liveness")
def health(state: StateDep, request: Request) -> dict[str, Any]:
    """``ok`` once the site is loaded, the store open and the tracker rebuilt."""
    return {
        "status": "ok",
        "schema_version": state.store.schema_version(),
        "last_seq": state.store.last_seq(),
        "viser_url": getattr(request.app.state, "viser_url", None),
    }


@router.get("/status", response_model=HealthOut, dependencies=READER, summary="Progress")
def status(state: StateDep) -> dict[str, Any]:
    """Row counts and stream state."""
    counts = state.store.counts()
    counts["ws_clients"] = len(state.hub.clients)
    counts["ws_dropped"] = state.hub.n_dropped
    counts["late_fixes"] = state.pipeline.n_late
    counts["ingest_commits"] = state.pipeline.n_commits  # group commit: batches per commit
    counts["ingest_batches"] = state.pipeline.n_batches
    return {
        "status": "ok",
        "schema_version": state.store.schema_version(),
        "last_seq": state.store.last_seq(),
        "counts": counts,
    }
