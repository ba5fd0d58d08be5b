"""``demtrack serve``: the operator console server (FastAPI on uvicorn)."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import Any

from .common import DEFAULT_SITE

__all__ = ["register"]


def _run(args: argparse.Namespace) -> int:
    import uvicorn

    from demtrack.server.app import create_app

    overrides: dict[str, Any] = {}
    if args.site is not None:
        overrides["site"] = args.site
    elif not os.environ.get("DEMTRACK_SITE"):
        overrides["site"] = DEFAULT_SITE
    if args.db is not None:
        overrides["db_path"] = args.db
    if args.no_warm_up:
        overrides["warm_up"] = False
    app = create_app(**overrides)
    settings = app.state.settings
    if app.state.token_generated:
        print(f"operator token (new; saved in {app.state.token_file}): {app.state.token}")
    elif app.state.token_file is not None:
        print(f"operator token: in {app.state.token_file}")
    else:
        print("operator token: as configured (DEMTRACK_TOKEN)")
    print(f"site {settings.site}, database {settings.resolved_db_path}", flush=True)
    uvicorn.run(
        app,
        host=args.host,
        port=args.port,
        log_level=args.log_level,
        ws_max_size=max(settings.max_ws_message_bytes * 2, 1 << 20),
        timeout_graceful_shutdown=5,
    )
    return 0


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
    p.add_argument("--port", type=int, default=8000, help="port (default 8000; 0 = any free)")
    p.add_argument(
        "--db",
        type=Path,
        default=None,
        metavar="PATH",
        help="SQLite file (default: DIR/console.sqlite3)",
    )
    p.add_argument(
        "--no-warm-up",
        action="store_true",
        help="do not compile the ray-casting kernels at start-up",
    )
    p.add_argument(
        "--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"]
    )
    p.set_defaults(func=_run)
