"""The operator console page: ``/`` and its static files.

Serves the browser console from the repository's ``web/`` folder: ``/`` is
``web/index.html``, ``/console/<file>`` our own scripts and styles (plain ES modules, no
bundler) and ``/vendor/ol/ol.js`` / ``ol.css`` OpenLayers from ``web/node_modules/ol``
(installed by ``npm ci --prefix web``; never committed). Nothing here needs the operator
token: the page holds no data; it asks for the token and sends it with every API call.

Only files inside those folders with a known suffix are served; a request path never
reaches the file system beyond them.
"""

from __future__ import annotations

import mimetypes
from pathlib import Path
from typing import Any

from fastapi import APIRouter, HTTPException, Request
from fastapi.responses import FileResponse, Response

__all__ = ["WEB_DIR", "router", "viser_url"]

#: The console's files (``web/`` at the repository root).
WEB_DIR = Path(__file__).resolve().parents[2] / "web"
_APP_DIR = WEB_DIR / "console"
_OL_FILES = {
    "ol.js": WEB_DIR / "node_modules" / "ol" / "dist" / "ol.js",
    "ol.css": WEB_DIR / "node_modules" / "ol" / "ol.css",
}
_TYPES = {
    ".html": "text/html; charset=utf-8",
    ".mjs": "text/javascript; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".json": "application/json",
    ".svg": "image/svg+xml",
    ".png": "image/png",
}
# The page is static and small; a short cache keeps reloads fast without going stale.
_CACHE = {"Cache-Control": "no-cache"}

mimetypes.add_type("text/javascript", ".mjs")

router = APIRouter(tags=["console"])


def _file(path: Path, root: Path) -> FileResponse:
    """``path`` if it is a plain file under ``root`` with a served suffix, else HTTP 404."""
    try:
        real = path.resolve(strict=True)
    except (OSError, RuntimeError, ValueError):  # ValueError: a NUL byte in the name
        raise HTTPException(404, "no such console file") from None
    media = _TYPES.get(real.suffix.lower())
    if media is None or not real.is_relative_to(root.resolve()) or not real.is_file():
        raise HTTPException(404, "no such console file")
    return FileResponse(real, media_type=media, headers=_CACHE)


@router.get("/", include_in_schema=False)
def index() -> FileResponse:
    """The console page."""
    return _file(WEB_DIR / "index.html", WEB_DIR)


@router.get("/console/{name:path}", include_in_schema=False)
def console_file(name: str) -> FileResponse:
    """One of the console's own scripts or styles."""
    if (
        not name
        or "\\" in name
        or "\x00" in name
        or any(p in ("", ".", "..") for p in name.split("/"))
    ):
        raise HTTPException(404, "no such console file")
    return _file(_APP_DIR / name, _APP_DIR)


@router.get("/vendor/ol/{name}", include_in_schema=False)
def openlayers(name: str) -> FileResponse:
    """OpenLayers' single-file build and stylesheet."""
    path = _OL_FILES.get(name)
    if path is None:
        raise HTTPException(404, "no such OpenLayers file")
    if not path.is_file():
        raise HTTPException(
            404, "OpenLayers is not installed: run `npm ci --prefix web` in the repository"
        )
    return _file(path, WEB_DIR / "node_modules" / "ol")


@router.get("/favicon.ico", include_in_schema=False)
def favicon() -> Response:
    """No icon (keeps the browser's console free of 404 noise)."""
    return Response(status_code=204)


def viser_url(request: Request) -> str | None:
    """The 3D view's URL if the server runs one (``app.state.viser_url`` or the state's)."""
    for holder in (request.app.state, getattr(request.app.state, "console", None)):
        url: Any = getattr(holder, "viser_url", None)
        if isinstance(url, str) and url:
            return url
    return None


#: Endpoints the page uses when the server has them (other parts of the API add them).
_OPTIONAL = {"events": "/api/events", "synopsis": "/api/synopsis", "export": "/api/tracks/export"}


@router.get("/console-config.json", include_in_schema=False)
def config(request: Request) -> dict[str, Any]:
    """What the page needs first: where the 3D view runs, which optional endpoints exist.

    Asking first keeps the browser's console free of 404s for endpoints a server lacks.
    """
    paths = set(request.app.openapi().get("paths", {}))  # built once, then cached
    return {
        "viser_url": viser_url(request),
        "endpoints": {name: path in paths for name, path in _OPTIONAL.items()},
    }
