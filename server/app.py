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
import sqlite3
import threading
import time
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from typing import Any

from fastapi import FastAPI
from fastapi.middleware.cors import CORSMiddleware
from pydantic import ValidationError
from starlette.concurrency import run_in_threadpool

from demtrack.core.errors import DemtrackError, SettingsError, SiteError
from demtrack.core.io.times import format_utc
from demtrack.core.site.folder import Site, load_site
from demtrack.core.tracking import METHODS
from demtrack.core.warm import SERVER_ENGINES, warm_up

from .api import (
    detections,
    docs,
    events,
    geolocate,
    heads,
    health,
    markers,
    scene3d,
    sensors,
    site,
    synopsis,
    tracks,
    video,
    visibility,
    web,
)
from .api.deps import READER
from .api.errors import error_responses, install_error_handlers
from .cluster.node import start_node
from .cot.service import start_cot_sender
from .heads.service import check_heads, start_heads
from .hub import Hub
from .ingest.pipeline import Pipeline, Publisher, pipeline_options
from .replay import Replay, scenario_stream, start_time_after
from .scenario_source import ScenarioSource
from .security import RequestGate, install_log_redaction, resolve_token
from .settings import Settings
from .state import ConsoleState
from .store.backend import StoreBackend
from .store.markers import list_markers
from .store.opening import open_store
from .stream import endpoint as stream
from .video.frames_http import frame_book
from .video.service import check_video_source, start_video_replay

__all__ = ["check_startup", "create_app"]

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
        if settings.replay_video:
            check_video_source(list(settings.replay), scenarios)
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


def _publish_nothing(messages: list[dict[str, Any]]) -> None:
    """The pipeline's publisher on PostgreSQL: the event log's follower publishes."""


def _start_scene(site_: Site, settings: Settings) -> Any:
    from .scene3d import Scene3D

    return Scene3D(
        site_, host=settings.viser_host, port=settings.viser_port, max_rays=settings.scene3d_rays
    )


def _start_replay(
    site_: Site,
    store: StoreBackend,
    pipeline: Pipeline,
    settings: Settings,
    scenarios: ScenarioSource,
    after: Any = None,
    send_poses: Any = None,
) -> Replay:
    """Start replaying ``settings.replay``; ``after`` (optional) is called before it plays.

    ``scenarios`` (``app.state.scenarios``, from :func:`create_app`) makes them.

    ``after`` (``app.state.replay_after``) runs in the replay thread once the scenarios are
    generated: ``demtrack demo`` sets it to wait for a child process compiling the
    tracker's kernels, so no replayed detection waits for (or repeats) that compile.
    """
    t0 = start_time_after(store.last_times())
    if settings.replay_start_s is not None:  # real UTC times, never before what is stored
        t0 = max(t0, float(settings.replay_start_s))
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
        send_poses=send_poses,
        speed=settings.replay_speed,
        min_interval_s=settings.replay_batch_s,
    )
    log.info(
        "replaying %s from %s at %g x", ", ".join(names), format_utc(t0, 0), settings.replay_speed
    )
    return replay.start()


def check_startup(app: FastAPI) -> None:
    """Load the site and open the database before the server starts, or raise one line.

    ``demtrack serve`` and ``demtrack demo`` call it before uvicorn runs: a failure
    inside the lifespan would reach the operator as uvicorn's traceback and "Application
    startup failed". The loaded site is kept (``app.state.preloaded_site``) for the
    lifespan, so nothing is read twice.

    Raises
    ------
    SiteError
        The site folder, a file it names (DEM, roads, images) or the database cannot be
        used; the message names the file and the problem.
    SettingsError
        The PostgreSQL database of ``database_url`` cannot be used (its URL is named
        without the password).
    """
    settings: Settings = app.state.settings
    app.state.preloaded_site = load_site(settings.site)
    check_heads(app.state.preloaded_site, settings)  # a bad head_adapter entry: one line
    if settings.database_url is not None:  # PostgreSQL: open_store words its own errors
        open_store(settings).close()
        return
    path = settings.resolved_db_path
    try:
        open_store(path).close()
    except sqlite3.DatabaseError as exc:
        raise SiteError(f"database {path} cannot be used: {exc}") from None
    except RuntimeError as exc:  # a newer schema
        raise SiteError(f"database {path}: {exc}") from None
    except OSError as exc:
        raise SiteError(f"database {path} cannot be opened: {exc.strerror or exc}") from None


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
    preloaded: Site | None = getattr(app.state, "preloaded_site", None)  # check_startup's
    site_ = (
        preloaded if preloaded is not None else await run_in_threadpool(load_site, settings.site)
    )
    store = open_store(settings)
    hub = Hub(settings.ws_queue_size)
    hub.bind(asyncio.get_running_loop())
    scene = await run_in_threadpool(_start_scene, site_, settings) if settings.scene3d else None
    app.state.scene3d = scene
    app.state.viser_url = None if scene is None else scene.url
    subscribers: list[Publisher] = [hub.publish_threadsafe]
    if scene is not None:
        subscribers.append(scene.publish)  # the 3D scene follows the same stream as /ws
    cot = None
    if settings.cot_url:  # CoT to TAK follows it too, through a queue that drops
        cot = await run_in_threadpool(
            start_cot_sender,
            settings.cot_url,
            site_,
            store.store_id,
            list_markers(store),
            track_stale_s=settings.cot_stale_s,
            marker_stale_s=settings.cot_marker_stale_s,
            queue_size=settings.cot_queue_size,
        )
        subscribers.append(cot.publish)
        log.info("sending CoT to %s", settings.cot_url)
    app.state.cot = cot
    # On PostgreSQL several processes share the database: the stream is published from
    # the event log, whoever wrote it (demtrack.server.cluster), never by the pipeline.
    shared = getattr(store, "kind", "sqlite") == "postgres"
    pipeline = Pipeline(
        site_,
        store,
        settings.tracker_method,
        _publish_nothing if shared else _fan_out(subscribers),
        **pipeline_options(settings),
    )
    caster = await run_in_threadpool(site_.dem.ray_caster)
    app.state.cluster = None
    if shared:
        app.state.cluster = await run_in_threadpool(
            start_node,
            store.url,  # type: ignore[attr-defined]
            pipeline,
            site_.name,
            settings.lease_ttl_s,
            _fan_out(subscribers),
        )
        counts = app.state.cluster.counts
    else:
        counts = await run_in_threadpool(pipeline.start)
    hub.last_seq = store.last_seq()
    app.state.schema_version = store.schema_version()  # /api/health reads no database
    log.info("replayed %(replayed)d fixes, processed %(processed)d detections", counts)
    app.state.console = ConsoleState(settings, site_, store, hub, pipeline, caster)
    app.state.heads = await run_in_threadpool(start_heads, app.state.console)
    app.state.replay = (
        start_video_replay(
            app.state.console,
            app.state.scenarios,
            frame_book(app.state),
            getattr(app.state, "replay_after", None),
        )
        if settings.replay and settings.replay_video
        else _start_replay(
            site_,
            store,
            pipeline,
            settings,
            app.state.scenarios,
            getattr(app.state, "replay_after", None),
            app.state.console.poses.accept_records,
        )
        if settings.replay
        else None
    )
    try:
        yield
    finally:
        if app.state.replay is not None:  # before the store closes: it ingests
            await run_in_threadpool(app.state.replay.stop)
        if app.state.heads is not None:  # it feeds poses into the store
            await run_in_threadpool(app.state.heads.stop)
        if app.state.cluster is not None:  # hands the lease over before the store closes
            await run_in_threadpool(app.state.cluster.stop)
        await run_in_threadpool(pipeline.close)  # its pose-message timer writes too
        if scene is not None:
            await run_in_threadpool(scene.stop)
        if cot is not None:
            await run_in_threadpool(cot.stop)
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
    if settings is None:
        try:
            settings = Settings(**overrides)
        except ValidationError as exc:  # a bad DEMTRACK_* variable or .env line, one line
            first = exc.errors()[0]
            name = ".".join(str(x) for x in first.get("loc", ())) or "settings"
            msg = str(first.get("msg", "invalid")).removeprefix("Value error, ")
            raise SettingsError(
                f"setting {name} (DEMTRACK_{name.upper()}): {msg}"
                + (f" (and {exc.error_count() - 1} more)" if exc.error_count() > 1 else "")
            ) from None
    _check(settings, scenarios)
    if not (settings.site / "site.json").is_file():
        raise SiteError(f"not a site folder (no site.json): {settings.site}")
    app = FastAPI(
        title="demtrack operator console",
        version="0.1.0",
        summary="Geolocate and track people and vehicles from calibrated cameras and a DEM.",
        lifespan=_lifespan,
        docs_url=None,  # /docs and /redoc come from api/docs.py, on local assets
        redoc_url=None,
    )
    app.state.settings = settings
    app.state.scenarios = scenarios
    app.state.token, app.state.token_file, app.state.token_generated = resolve_token(settings)
    install_log_redaction()
    # The token before any body is read, then the size limit (inside CORS, so a refusal
    # still carries CORS headers).
    app.add_middleware(RequestGate, max_body_bytes=settings.max_body_bytes)
    if settings.cors_origins:
        app.add_middleware(
            CORSMiddleware,
            allow_origins=settings.cors_origins,
            allow_methods=["GET", "POST"],
            allow_headers=["Authorization", "Content-Type", "X-Demtrack-Token"],
        )
    install_error_handlers(app)
    # The error statuses each router's routes can answer (OpenAPI `responses`).
    read = error_responses(401, 404, 422)
    app.include_router(health.router)
    app.include_router(site.router, dependencies=READER, responses=read)
    app.include_router(sensors.router, dependencies=READER, responses=read)
    app.include_router(heads.router)  # its routes name their own token checks
    app.include_router(geolocate.router, dependencies=READER, responses=read)
    app.include_router(detections.router)  # its routes name their own statuses
    app.include_router(tracks.router, dependencies=READER, responses=read)
    app.include_router(synopsis.router, dependencies=READER, responses=read)
    app.include_router(events.router, dependencies=READER, responses=read)
    # markers' routes name their own token checks
    app.include_router(markers.router, responses=error_responses(401, 404, 422, 503, 507))
    app.include_router(visibility.router, dependencies=READER, responses=read)
    app.include_router(video.router)  # frames in and out; its routes name their token checks
    app.include_router(scene3d.router, responses=read)
    app.include_router(stream.router)
    app.include_router(web.router)
    app.include_router(docs.router)
    return app
