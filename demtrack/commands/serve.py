"""``demtrack serve``: the operator console server (FastAPI on uvicorn)."""

from __future__ import annotations

import argparse
import os
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

from demtrack.server.gc_tuning import SERVER_GC_THRESHOLDS, tune_gc_for_serving

from .choices import REPLAY_NAMES
from .common import DEFAULT_SITE, port

__all__ = [
    "SERVER_GC_THRESHOLDS",
    "VIDEO_DEFAULT",
    "VIDEO_NAMES",
    "scenario_source",
    "add_live_arguments",
    "live_overrides",
    "print_token",
    "register",
    "serve_app",
    "tune_gc_for_serving",
]


#: ``demtrack.samplesite.video_cache.VIDEO_SCENARIOS``: what ``--video`` can play.
VIDEO_NAMES = ("vehicle-run", "pedestrians", "passing-vehicles")
#: What ``--video`` replays by default.
VIDEO_DEFAULT = ("vehicle-run", "pedestrians")


def scenario_source(live: dict[str, Any]) -> Any:
    """The sample site's scenario source; with ``--video``, the one that renders videos."""
    from demtrack.samplesite.replay_source import SAMPLE_SCENARIOS

    if not live.get("replay_video"):
        return SAMPLE_SCENARIOS
    from demtrack.samplesite.video_cache import SampleVideos

    return SampleVideos(log=lambda line: print(f"video: {line}", flush=True))


def serve_app(
    app: Any,
    host: str,
    port: int,
    log_level: str = "info",
    on_ready: Callable[[int], None] | None = None,
) -> int:
    """Run ``app`` on uvicorn until Ctrl-C / SIGTERM; returns the exit status.

    Parameters
    ----------
    app : FastAPI
        From :func:`demtrack.server.app.create_app`.
    host, port : str, int
        Address to bind (port 0 = any free one).
    log_level : str
        uvicorn's log level.
    on_ready : callable, optional
        Called with the bound port once start-up (site, store, tracker, warm-up) is
        done and the first request can be served.

    Returns
    -------
    int
        0 after a clean shutdown (Ctrl-C included), 1 if start-up failed.
    """
    import uvicorn

    settings = app.state.settings
    config = uvicorn.Config(
        app,
        host=host,
        port=port,
        log_level=log_level,
        ws_max_size=max(settings.max_ws_message_bytes * 2, 1 << 20),
        ws_per_message_deflate=settings.ws_compression,
        timeout_graceful_shutdown=5,
    )
    # uvicorn.Config has just (re)configured logging: keep ?token=... out of its lines.
    from demtrack.server.security import install_log_redaction

    install_log_redaction()
    server = uvicorn.Server(config)
    done = threading.Event()

    def watch() -> None:
        while not done.wait(0.05):
            if server.started:
                tune_gc_for_serving()
                if on_ready is not None:
                    on_ready(int(server.servers[0].sockets[0].getsockname()[1]))
                return

    threading.Thread(target=watch, name="demtrack-ready", daemon=True).start()
    try:
        server.run()
    except KeyboardInterrupt:  # uvicorn re-raises Ctrl-C after its graceful shutdown
        if not server.started:
            raise
    finally:
        done.set()
    return 0 if server.started else 1


def print_token(app: Any) -> None:
    """Say where the operator token comes from (printed in full only when new)."""
    if app.state.token_generated:
        print(f"operator token (new; saved in {app.state.token_file}): {app.state.token}")
    elif app.state.token_file is not None:
        print(f"operator token: in {app.state.token_file}")
    else:
        print("operator token: as configured (DEMTRACK_TOKEN)")


def add_live_arguments(p: argparse.ArgumentParser, *, replay_default: list[str]) -> None:
    """Options shared by ``serve`` and ``demo``: scenario replay and the 3D scene."""
    shown = ",".join(replay_default) or "none"
    p.add_argument(
        "--replay",
        action="append",
        choices=REPLAY_NAMES,
        default=None,
        metavar="SCENARIO",
        help=f"replay a sample-site scenario live (repeatable: {', '.join(REPLAY_NAMES)};"
        f" default {shown})",
    )
    p.add_argument(
        "--speed",
        type=float,  # checked in live_overrides, with the option named
        default=1.0,
        metavar="X",
        help="replay speed, times real time (default 1)",
    )
    p.add_argument(
        "--start",
        metavar="ISO8601",
        default="now",
        help="UTC time the replay starts at, e.g. 2026-12-01T14:30:00Z (default now):"
        " replayed detections carry real times from it",
    )
    p.add_argument(
        "--video",
        action="store_true",
        help="replay from video: each camera's video of the scenario (rendered once into"
        " SITE/videos/, then reused) goes through the video detector, and the camera panels"
        " show it (scenarios: vehicle-run, pedestrians, passing-vehicles; default"
        " vehicle-run and pedestrians)",
    )
    p.add_argument(
        "--viser-port",
        type=int,  # checked in live_overrides, with the option named
        default=8080,
        metavar="PORT",
        help="port of the 3D scene (default 8080, 0 = any free; a busy one moves)",
    )


def live_overrides(args: argparse.Namespace, replay_default: list[str]) -> dict[str, Any]:
    """Settings for the replay and 3D options."""
    import math

    from demtrack.core.errors import DemtrackError

    if not (math.isfinite(args.speed) and args.speed > 0):
        raise DemtrackError(f"--speed must be a positive number, got {args.speed}")
    if not 0 <= args.viser_port <= 65535:
        raise DemtrackError(f"--viser-port must be within 0..65535, got {args.viser_port}")
    from demtrack.samplesite.stamping import parse_start

    video = bool(getattr(args, "video", False))
    if video and not args.replay:
        replay_default = list(VIDEO_DEFAULT)
    replay = list(dict.fromkeys(args.replay)) if args.replay else list(replay_default)
    if video:
        bad = [name for name in replay if name not in VIDEO_NAMES]
        if bad:
            raise DemtrackError(
                f"--video cannot play {bad[0]!r}: the sample-video renderer draws"
                f" {', '.join(VIDEO_NAMES)}"
            )
    return {
        "replay": replay,
        "replay_video": video,
        "replay_start_s": parse_start(args.start),
        "replay_speed": args.speed,
        "viser_host": args.host,
        "viser_port": args.viser_port,
    }


def _run(args: argparse.Namespace) -> int:
    from demtrack.server.app import check_startup, create_app

    live = live_overrides(args, [])  # checks --speed and --viser-port before any work
    overrides: dict[str, Any] = {}
    if args.site is not None:
        overrides["site"] = args.site
    elif not os.environ.get("DEMTRACK_SITE"):
        overrides["site"] = DEFAULT_SITE
    if args.db is not None:
        overrides["db_path"] = args.db
    if args.database_url is not None:
        overrides["database_url"] = args.database_url
    if args.no_warm_up:
        overrides["warm_up"] = False
    if args.video and not args.replay:
        from demtrack.core.errors import DemtrackError

        raise DemtrackError("--video plays a replay: give --replay SCENARIO too")
    if args.replay:
        overrides.update(live)
    if args.scene3d:
        overrides.update(scene3d=True, viser_host=args.host, viser_port=args.viser_port)
    if args.cot is not None:
        overrides["cot_url"] = args.cot
    if args.heads is not None:
        overrides["heads"] = args.heads
    app = create_app(scenarios=scenario_source(live), **overrides)  # the sample's scenarios
    check_startup(app)  # a broken site or database: one line and exit 2, not a traceback
    settings = app.state.settings
    print_token(app)
    print(f"site {settings.site}, database {settings.database_label}", flush=True)

    def ready(port: int) -> None:
        if app.state.viser_url is not None:
            print(f"3D view: {app.state.viser_url}", flush=True)

    return serve_app(app, args.host, args.port, args.log_level, on_ready=ready)


def register(sub: argparse._SubParsersAction) -> None:
    """Add the ``serve`` command."""
    p = sub.add_parser(
        "serve",
        help="run the operator console server",
        description="Serve the console API and live stream for a site. Settings also come from"
        " DEMTRACK_* environment variables and .env (DEMTRACK_TOKEN, DEMTRACK_OPEN_READS,"
        " DEMTRACK_CORS_ORIGINS, ...); see docs/server.md.",
    )
    p.add_argument(
        "--site",
        type=Path,
        default=None,
        metavar="DIR",
        help=f"site folder (default: $DEMTRACK_SITE, else {DEFAULT_SITE})",
    )
    p.add_argument("--host", default="127.0.0.1", help="address to bind (default 127.0.0.1)")
    p.add_argument("--port", type=port, default=8000, help="port (default 8000; 0 = any free)")
    p.add_argument(
        "--db",
        type=Path,
        default=None,
        metavar="PATH",
        help="SQLite file (default: DIR/console.sqlite3)",
    )
    p.add_argument(
        "--database-url",
        default=None,
        metavar="URL",
        help="keep the store on PostgreSQL + PostGIS instead: postgresql://USER@HOST:PORT/DB"
        " (default: $DEMTRACK_DATABASE_URL, else the SQLite file; see docs/postgres.md)",
    )
    p.add_argument(
        "--no-warm-up",
        action="store_true",
        help="do not compile the ray-casting kernels at start-up",
    )
    p.add_argument(
        "--3d",
        dest="scene3d",
        action="store_true",
        help="also serve the viser 3D scene (on --viser-port)",
    )
    p.add_argument(
        "--cot",
        default=None,
        metavar="URL",
        help="send tracks and markers as Cursor-on-Target to a TAK peer: udp://239.2.3.1:6969"
        " (multicast; ?ttl=N), udp://HOST:PORT or tcp://HOST:8087 (default: $DEMTRACK_COT_URL)",
    )
    p.add_argument(
        "--heads",
        choices=["auto", "sim", "off"],
        default=None,
        help="pan-tilt-zoom heads of the site's active sensors: auto (those site.json gives a"
        " head_adapter: ONVIF or simulated), sim (also simulate the others) or off"
        " (default: $DEMTRACK_HEADS, else auto)",
    )
    add_live_arguments(p, replay_default=[])
    p.add_argument(
        "--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"]
    )
    p.set_defaults(func=_run)
