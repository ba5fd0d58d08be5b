"""``/docs`` (Swagger UI) and ``/redoc`` (ReDoc), served from local files.

FastAPI's own pages load Swagger UI and ReDoc from a CDN (and ReDoc's fonts from Google),
so offline they are blank. These pages load the same scripts from the npm packages
``swagger-ui-dist`` and ``redoc`` in ``web/node_modules`` (installed by
``npm ci --prefix web``, as OpenLayers is; never committed), under
``/vendor/swagger-ui/`` and ``/vendor/redoc/`` (ReDoc's bundle with the one image it
would fetch from a CDN, its maker's logo, replaced by an empty one). The operator token
is declared in the OpenAPI document as the ``operatorToken`` bearer scheme
(:data:`demtrack.server.security.BEARER`): Swagger UI's *Authorize* button takes it and
sends it with *Try it out*, so the docs page can call the write endpoints.
"""

from __future__ import annotations

import functools
from pathlib import Path

from fastapi import APIRouter, HTTPException, Request
from fastapi.openapi.docs import (
    get_redoc_html,
    get_swagger_ui_html,
    get_swagger_ui_oauth2_redirect_html,
)
from fastapi.responses import FileResponse, HTMLResponse, Response

from .web import WEB_DIR

__all__ = ["DOCS_FILES", "router"]

_MODULES = WEB_DIR / "node_modules"
#: Files the docs pages load, by URL name (nothing else under node_modules is served).
DOCS_FILES: dict[str, dict[str, tuple[Path, str]]] = {
    "swagger-ui": {
        "swagger-ui-bundle.js": (
            _MODULES / "swagger-ui-dist" / "swagger-ui-bundle.js",
            "text/javascript; charset=utf-8",
        ),
        "swagger-ui.css": (
            _MODULES / "swagger-ui-dist" / "swagger-ui.css",
            "text/css; charset=utf-8",
        ),
        "favicon-32x32.png": (_MODULES / "swagger-ui-dist" / "favicon-32x32.png", "image/png"),
    },
    "redoc": {
        "redoc.standalone.js": (
            _MODULES / "redoc" / "bundles" / "redoc.standalone.js",
            "text/javascript; charset=utf-8",
        ),
    },
}
_PACKAGE = {"swagger-ui": "swagger-ui-dist", "redoc": "redoc"}
_FAVICON = "/vendor/swagger-ui/favicon-32x32.png"
# Swagger UI's defaults, less the online validator (a request to validator.swagger.io).
_SWAGGER_PARAMETERS = {
    "dom_id": "#swagger-ui",
    "layout": "BaseLayout",
    "deepLinking": True,
    "showExtensions": True,
    "showCommonExtensions": True,
    "validatorUrl": None,
}

router = APIRouter(tags=["docs"])


def _openapi_url(request: Request) -> str:
    return request.scope.get("root_path", "").rstrip("/") + (request.app.openapi_url or "")


@router.get("/docs", include_in_schema=False)
def swagger_ui(request: Request) -> HTMLResponse:
    """Swagger UI on this server's OpenAPI document, from local assets."""
    return get_swagger_ui_html(
        openapi_url=_openapi_url(request),
        title=f"{request.app.title} - API (Swagger UI)",
        swagger_js_url="/vendor/swagger-ui/swagger-ui-bundle.js",
        swagger_css_url="/vendor/swagger-ui/swagger-ui.css",
        swagger_favicon_url=_FAVICON,
        oauth2_redirect_url="/docs/oauth2-redirect",
        swagger_ui_parameters=_SWAGGER_PARAMETERS,
    )


@router.get("/docs/oauth2-redirect", include_in_schema=False)
def swagger_ui_redirect() -> HTMLResponse:
    """Swagger UI's OAuth2 redirect page (unused by the bearer token; kept for the UI)."""
    return get_swagger_ui_oauth2_redirect_html()


@router.get("/redoc", include_in_schema=False)
def redoc(request: Request) -> HTMLResponse:
    """ReDoc on this server's OpenAPI document, from local assets, without web fonts."""
    return get_redoc_html(
        openapi_url=_openapi_url(request),
        title=f"{request.app.title} - API (ReDoc)",
        redoc_js_url="/vendor/redoc/redoc.standalone.js",
        redoc_favicon_url=_FAVICON,
        with_google_fonts=False,
    )


#: ReDoc's sidebar footer loads its maker's logo from their CDN (hard-coded in the
#: bundle, no option turns it off): served with the logo swapped for an empty image.
_REDOC_CDN_LOGO = b"https://cdn.redoc.ly/redoc/logo-mini.svg"
_EMPTY_SVG = b"data:image/svg+xml,%3Csvg xmlns='http://www.w3.org/2000/svg'/%3E"


@functools.lru_cache(maxsize=1)
def _redoc_bundle(path: Path, mtime_ns: int) -> bytes:
    return path.read_bytes().replace(_REDOC_CDN_LOGO, _EMPTY_SVG)


def _asset(package: str, name: str) -> Response:
    entry = DOCS_FILES[package].get(name)
    if entry is None:
        raise HTTPException(404, f"no such file: /vendor/{package}/{name}")
    path, media = entry
    if not path.is_file():
        raise HTTPException(
            404,
            f"{_PACKAGE[package]} is not installed: run `npm ci --prefix web` in the repository",
        )
    headers = {"Cache-Control": "no-cache"}
    if name == "redoc.standalone.js":
        data = _redoc_bundle(path, path.stat().st_mtime_ns)
        return Response(data, media_type=media, headers=headers)
    return FileResponse(path, media_type=media, headers=headers)


@router.get("/vendor/swagger-ui/{name}", include_in_schema=False)
def swagger_asset(name: str) -> Response:
    """One of Swagger UI's files in :data:`DOCS_FILES` (by name from the table, not a path)."""
    return _asset("swagger-ui", name)


@router.get("/vendor/redoc/{name}", include_in_schema=False)
def redoc_asset(name: str) -> Response:
    """ReDoc's standalone bundle (by name from :data:`DOCS_FILES`, not a path)."""
    return _asset("redoc", name)
