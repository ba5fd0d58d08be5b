"""Fixtures for the browser tests: real uvicorn servers on the sample site, Chromium.

Chromium is Debian's (``/usr/bin/chromium``), driven headless by Playwright's sync API;
OpenLayers must be installed (``npm ci --prefix web``): both are part of the test set-up,
so their absence fails the tests instead of skipping them.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest
from web_helpers import (
    CHROMIUM,
    LAUNCH_ARGS,
    LOOPBACK,
    OL_JS,
    SCENARIO,
    SHOTS,
    PageRecord,
    Server,
    free_port,
    post_until,
)


@pytest.fixture(scope="session")
def ol_installed() -> Path:
    """OpenLayers from npm; installed by the set-up (``npm ci --prefix web``)."""
    if not OL_JS.is_file():
        pytest.fail(f"OpenLayers is missing ({OL_JS}): run `npm ci --prefix web` first")
    return OL_JS


@pytest.fixture(scope="session")
def scenario_records(sample_site_dir: Path) -> list[dict[str, Any]]:
    """The scenario's detection records (the ingest format), in time order."""
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.scenarios import make_scenario

    scenario = make_scenario(load_site(sample_site_dir), SCENARIO)
    return [
        {
            "t": d.t_s,
            "sensor": d.sensor,
            "bbox": list(d.bbox),
            "class": d.cls,
            "score": d.score,
        }
        for d in scenario.detections
    ]


@pytest.fixture
def server_factory(sample_site_dir: Path, tmp_path: Path) -> Iterator[Any]:
    """``server_factory()`` -> a started server on a fresh database."""
    servers: list[Server] = []

    def make(name: str = "console") -> Server:
        srv = Server(sample_site_dir, tmp_path / f"{name}.sqlite3", free_port()).start()
        servers.append(srv)
        return srv

    yield make
    for s in servers:
        s.stop()


@pytest.fixture(scope="module")
def fed_server(
    sample_site_dir: Path, tmp_path_factory: pytest.TempPathFactory, scenario_records
) -> Iterator[Server]:
    """One server per module with the whole scenario ingested."""
    tmp = tmp_path_factory.mktemp("fed")
    srv = Server(sample_site_dir, tmp / "console.sqlite3", free_port()).start()
    try:
        with srv.client() as c:
            post_until(c, scenario_records, -1.0, 1e9, step_s=5.0)
        yield srv
    finally:
        srv.stop()


@pytest.fixture(scope="session")
def browser(ol_installed: Path) -> Iterator[Any]:
    """Debian's Chromium, headless."""
    from playwright.sync_api import sync_playwright

    if not CHROMIUM.is_file():
        pytest.fail(f"Chromium is missing ({CHROMIUM}): apt-get install -y chromium")
    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=str(CHROMIUM), headless=True, args=LAUNCH_ARGS)
        yield b
        b.close()


@pytest.fixture
def page(browser: Any, request: pytest.FixtureRequest) -> Iterator[Any]:
    """A 1280 x 800 page that records errors and requests; saves a screenshot at the end.

    Requests to anything but loopback are aborted (and recorded), so a test fails
    rather than reaching the network.
    """
    context = browser.new_context(viewport={"width": 1280, "height": 800}, accept_downloads=True)
    pg = context.new_page()
    rec = PageRecord()

    def route(r: Any) -> None:
        host = urlsplit(r.request.url).hostname
        if host in LOOPBACK:
            r.continue_()
        else:
            rec.blocked.append(r.request.url)
            r.abort()

    context.route(re.compile(r"^(https?|wss?)://"), route)
    pg.on("console", lambda m: rec.errors.append(m.text) if m.type == "error" else None)
    pg.on("pageerror", lambda e: rec.errors.append(f"uncaught: {e}"))
    pg.on("request", lambda r: rec.requests.append(r.url))
    pg.on("websocket", lambda ws: rec.websockets.append(ws.url))
    pg.record = rec
    yield pg
    SHOTS.mkdir(parents=True, exist_ok=True)
    name = re.sub(r"[^A-Za-z0-9_.-]+", "_", request.node.name)
    try:
        pg.screenshot(path=str(SHOTS / f"{name}.png"))
    finally:
        context.close()
