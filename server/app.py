"""The FastAPI application factory and its lifespan.

``create_app(settings, scenarios=...)`` builds the settings (arguments, then
``DEMTRACK_*`` environment, then ``.env``), the routers (:mod:`demtrack.server.api`, the
stream :mod:`demtrack.server.stream`) and the error handlers
(:mod:`demtrack.server.api.errors`); the site, the store, the tracker replay and the
numba warm-up happen in the lifespan, when the server starts. The scenarios a live
replay plays come from the caller (a
:class:`~demtrack.server.scenario_source.ScenarioSource`): the server generates none.
"""

from __future__ import annotations

import asyncio
import json
import logging
import threading
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from starlette.concurrency import run_in_threadpool

from demtrack.core.errors import DemtrackError, SiteError
from demtrack.core.site.folder import Site, load_site
from demtrack.core.tracking import METHODS
from demtrack.core.warm import SERVER_ENGINES, warm_up

from .api import (
    detections,
    events,
    geolocate,
    health,
    scene3d,
    sensors,
    site,
    synopsis,
    tracks,
    visibility,
    web,
)
from .api.deps import READER
from .api.errors import install_error_handlers
from .hub import Hub
from .ingest.pipeline import Pipeline, Publisher, pipeline_options
from .replay import Replay, scenario_stream, start_time_after
from .scenario_source import ScenarioSource
from .security import resolve_token
from .settings import Settings
from .state import ConsoleState
from .store.database import Store
from .stream import endpoint as stream

__all__ = ["create_app"]

log = logging.getLogger("demtrack.server")


def _check(settings: Settings, scenarios: ScenarioSource | None) -> None:
    if settings.tracker_method not in METHODS:
        raise DemtrackError(
            f"unknown tracker method {settings.tracker_method!r}; known: {', '.join(METHODS)}"
        )
    if settings.replay:
        if scenarios is None:
            raise DemtrackError(
                f"cannot replay {', '.join(settings.replay)}: no scenario source was handed to"
                " create_app (demtrack serve and demtrack demo hand the sample site's)"
            )
        known = list(scenarios.names)
        unknown = [name for name in settings.replay if name not in known]
        if unknown:
            raise DemtrackError(
                f"unknown replay scenario {unknown[0]!r}; known: {', '.join(sorted(known))}"
            )
        try:
            doc = json.loads((settings.site / "site.json").read_text("utf-8"))
        except (OSError, ValueError):
            return  # create_app reports the missing or broken site itself
        if not isinstance(doc, dict) or "seed" not in (doc.get("generator") or {}):
            raise SiteError(
                f"cannot replay {', '.join(settings.replay)}: {settings.site} is not a"
                " generated sample site (demtrack sample-site makes one)"
            )


def _warm_kernels(done: threading.Event, after: Any = None) -> None:
    """Compile (or load from numba's cache) the kernels requests use, then set ``done``.

    Run in a thread at start-up: from the on-disk cache this takes about a second; a cold
    compile takes minutes of CPU on two cores, and the first page, the site and the
    imagery are served meanwhile (a request that casts rays waits for its kernel).
    ``after`` (``app.state.warm_after``, optional) is called first: ``demtrack demo`` sets
    it to wait for a child process already compiling these kernels into numba's cache.
    """
    t0 = time.perf_counter()
    try:
        if after is not None:
            after()
        # Ray casts (small batches: the pyramid walk only), lens, surface, live tracker.
        warm_up(SERVER_ENGINES, angular=False)
        log.info("ray-casting kernels ready in %.1f s", time.perf_counter() - t0)
    except Exception:  # noqa: BLE001 - a failed warm-up only costs the first request time
        log.exception("kernel warm-up failed")
    finally:
        done.set()


def _fan_out(publishers: list[Publisher]) -> Publisher:
    """One publisher that hands each batch of messages to every subscriber in turn."""

    def publish(messages: list[dict[str, Any]]) -> None:
        for p in publishers:
            p(messages)

    return publish


def _start_scene(site_: Site, settings: Settings) -> Any:
    from .scene3d import Scene3D

    return Scene3D(
        site_, host=settings.viser_host, port=settings.viser_port, max_rays=settings.scene3d_rays
    )


def _start_replay(
    site_: Site,
    store: Store,
    pipeline: Pipeline,
    settings: Settings,
    scenarios: ScenarioSource,
    after: Any = None,
) -> Replay:
    """Start replaying ``settings.replay``; ``after`` (optional) is called before it plays.

    ``scenarios`` (``app.state.scenarios``, from :func:`create_app`) makes them.

    ``after`` (``app.state.replay_after``) runs in the replay thread once the scenarios are
    generated: ``demtrack demo`` sets it to wait for a child process compiling the
    tracker's kernels, so no replayed detection waits for (or repeats) that compile.
    """
    t0 = start_time_after(store.last_times())
    names = list(settings.replay)

    def frames() -> Any:
        stream = scenario_stream(
            site_,
            names,
            t0,
            source=scenarios,
            loop=settings.replay_loop,
            copies=settings.replay_copies,
            rate_hz=settings.replay_rate_hz,
            duration_s=settings.replay_duration_s or None,
        )
        if after is not None:
            after()
        return stream

    replay = Replay(
        frames,
        pipeline.ingest,
        speed=settings.replay_speed,
        min_interval_s=settings.replay_batch_s,
    )
    log.info("replaying %s from t = %.0f s at %g x", ", ".join(names), t0, settings.replay_speed)
    return replay.start()


@asynccontextmanager
async def _lifespan(app: FastAPI) -> AsyncIterator[None]:
    settings: Settings = app.state.settings
    app.state.warm = threading.Event()
    if settings.warm_up:  # compiles in the background: the first page need not wait for it
        threading.Thread(
            target=_warm_kernels,
            args=(app.state.warm, getattr(app.state, "warm_after", None)),
            name="demtrack-warm-up",
            daemon=True,
        ).start()
    else:
        app.state.warm.set()
    site_ = await run_in_threadpool(load_site, settings.site)
    store = Store(settings.resolved_db_path)
    hub = Hub(settings.ws_queue_size)
    hub.bind(asyncio.get_running_loop())
    scene = await run_in_threadpool(_start_scene, site_, settings) if settings.scene3d else None
    app.state.scene3d = scene
    app.state.viser_url = None if scene is None else scene.url
    subscribers: list[Publisher] = [hub.publish_threadsafe]
    if scene is not None:
        subscribers.append(scene.publish)  # the 3D scene follows the same stream as /ws
    pipeline = Pipeline(
        site_, store, settings.tracker_method, _fan_out(subscribers), **pipeline_options(settings)
    )
    caster = await run_in_threadpool(site_.dem.ray_caster)
    counts = await run_in_threadpool(pipeline.start)
    hub.last_seq = store.last_seq()
    log.info("replayed %(replayed)d fixes, processed %(processed)d detections", counts)
    app.state.console = ConsoleState(settings, site_, store, hub, pipeline, caster)
    app.state.replay = (
        _start_replay(
            site_,
            store,
            pipeline,
            settings,
            app.state.scenarios,
            getattr(app.state, "replay_after", None),
        )
        if settings.replay
        else None
    )
    try:
        yield
    finally:
        if app.state.replay is not None:  # before the store closes: it ingests
            await run_in_threadpool(app.state.replay.stop)
        if scene is not None:
            await run_in_threadpool(scene.stop)
        hub.bind(None)  # type: ignore[arg-type]
        store.close()


def create_app(
    settings: Settings | None = None,
    *,
    scenarios: ScenarioSource | None = None,
    **overrides: Any,
) -> FastAPI:
    """Build the console's FastAPI app.

    Parameters
    ----------
    settings : Settings, optional
        Complete settings; when None they are read from ``overrides`` (keyword arguments
        named as the :class:`Settings` fields), the ``DEMTRACK_*`` environment and ``.env``.
    scenarios : ScenarioSource, optional
        Makes the scenarios ``settings.replay`` names (needed only for a replay):
        ``demtrack.samplesite.replay_source.SAMPLE_SCENARIOS`` for the sample site.

    Raises
    ------
    DemtrackError
        On settings that cannot work (missing site folder, unknown tracker method, a
        replay without a scenario source or of a scenario it does not know).

    Notes
    -----
    The operator token is resolved here (configured, or read from / written to
    ``<db>.token``): ``app.state.token``, ``app.state.token_file`` and
    ``app.state.token_generated`` tell the caller what to print.
    """
    settings = settings if settings is not None else Settings(**overrides)
    _check(settings, scenarios)
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
    app.state.scenarios = scenarios
    app.state.token, app.state.token_file, app.state.token_generated = resolve_token(settings)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST"],
            allow_headers=["Authorization", "Content-Type", "X-Demtrack-Token"],
        )
    install_error_handlers(app)
    app.include_router(health.router)
    app.include_router(site.router, dependencies=READER)
    app.include_router(sensors.router, dependencies=READER)
    app.include_router(geolocate.router, dependencies=READER)
    app.include_router(detections.router)
    app.include_router(tracks.router, dependencies=READER)
    app.include_router(synopsis.router, dependencies=READER)
    app.include_router(events.router, dependencies=READER)
    app.include_router(visibility.router, dependencies=READER)
    app.include_router(scene3d.router)
    app.include_router(stream.router)
    app.include_router(web.router)
    return app
