"""The FastAPI application factory and its lifespan.

``create_app(settings)`` builds the settings (arguments, then ``DEMTRACK_*`` environment,
then ``.env``), the routers and the error handlers; the site, the store, the tracker
replay and the numba warm-up happen in the lifespan, when the server starts.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import Depends, FastAPI, Request
from fastapi.encoders import jsonable_encoder
from fastapi.exceptions import RequestValidationError
from fastapi.middleware.cors import CORSMiddleware
from fastapi.responses import JSONResponse
from starlette.concurrency import run_in_threadpool

from demtrack.core.errors import DemtrackError, SiteError
from demtrack.core.raycast import warm_up
from demtrack.core.site import load_site
from demtrack.core.tracking import METHODS

from .db import Store
from .hub import Hub
from .pipeline import Pipeline
from .routers import detections, geolocate, health, sensors, site, stream, tracks
from .security import require_reader, resolve_token
from .settings import Settings
from .state import ConsoleState

__all__ = ["create_app"]

log = logging.getLogger("demtrack.server")


def _validation_detail(errors: list[dict[str, Any]]) -> tuple[str, list[dict[str, Any]]]:
    """One readable line, and the errors without the offending input (NaN, or large)."""
    clean, parts = [], []
    for e in errors:
        loc = [str(x) for x in e.get("loc", ())]
        msg = str(e.get("msg", "invalid"))
        clean.append({"loc": loc, "msg": msg, "type": str(e.get("type", ""))})
        parts.append(f"{'.'.join(loc)}: {msg}" if loc else msg)
    shown = "; ".join(parts[:5]) + (f" (and {len(parts) - 5} more)" if len(parts) > 5 else "")
    return shown, jsonable_encoder(clean)


async def _on_validation(request: Request, exc: RequestValidationError) -> JSONResponse:
    detail, errors = _validation_detail(list(exc.errors()))
    return JSONResponse({"detail": detail, "errors": errors}, status_code=422)


async def _on_demtrack(request: Request, exc: Exception) -> JSONResponse:
    code = 404 if isinstance(exc, SiteError) and "unknown" in str(exc) else 422
    return JSONResponse({"detail": str(exc)}, status_code=code)


def _check(settings: Settings) -> None:
    if settings.tracker_method not in METHODS:
        raise DemtrackError(
            f"unknown tracker method {settings.tracker_method!r}; known: {', '.join(METHODS)}"
        )


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings: Settings = app.state.settings
    if settings.warm_up:
        await run_in_threadpool(warm_up)
    site_ = await run_in_threadpool(load_site, settings.site)
    store = Store(settings.resolved_db_path)
    hub = Hub(settings.ws_queue_size)
    hub.bind(asyncio.get_running_loop())
    pipeline = Pipeline(site_, store, settings.tracker_method, hub.publish_threadsafe)
    caster = await run_in_threadpool(site_.dem.ray_caster)
    replay = await run_in_threadpool(pipeline.start)
    hub.last_seq = store.last_seq()
    log.info("replayed %(replayed)d fixes, processed %(processed)d detections", replay)
    app.state.console = ConsoleState(settings, site_, store, hub, pipeline, caster)
    try:
        yield
    finally:
        hub.bind(None)  # type: ignore[arg-type]
        store.close()


def create_app(settings: Settings | None = None, **overrides: Any) -> FastAPI:
    """Build the console's FastAPI app.

    Parameters
    ----------
    settings : Settings, optional
        Complete settings; when None they are read from ``overrides`` (keyword arguments
        named as the :class:`Settings` fields), the ``DEMTRACK_*`` environment and ``.env``.

    Raises
    ------
    DemtrackError
        On settings that cannot work (missing site folder, unknown tracker method).

    Notes
    -----
    The operator token is resolved here (configured, or read from / written to
    ``<db>.token``): ``app.state.token``, ``app.state.token_file`` and
    ``app.state.token_generated`` tell the caller what to print.
    """
    settings = settings if settings is not None else Settings(**overrides)
    _check(settings)
    if not (settings.site / "site.json").is_file():
        raise SiteError(f"not a site folder (no site.json): {settings.site}")
    app = FastAPI(
        title="demtrack operator console",
        version="0.1.0",
        summary="Geolocate and track people and vehicles from calibrated cameras and a DEM.",
        lifespan=_lifespan,
        max_body_size=settings.max_body_bytes,
    )
    app.state.settings = settings
    app.state.token, app.state.token_file, app.state.token_generated = resolve_token(settings)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST"],
            allow_headers=["Authorization", "Content-Type", "X-Demtrack-Token"],
        )
    app.add_exception_handler(RequestValidationError, _on_validation)  # type: ignore[arg-type]
    app.add_exception_handler(DemtrackError, _on_demtrack)
    reader = [Depends(require_reader)]
    app.include_router(health.router)
    app.include_router(site.router, dependencies=reader)
    app.include_router(sensors.router, dependencies=reader)
    app.include_router(geolocate.router, dependencies=reader)
    app.include_router(detections.router)
    app.include_router(tracks.router, dependencies=reader)
    app.include_router(stream.router)
    return app
