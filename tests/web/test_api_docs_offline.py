"""``/docs`` and ``/redoc`` render offline, and Swagger UI can call a write endpoint.

Chromium loads each page from a real ``demtrack serve`` while every request off loopback
is aborted (the ``page`` fixture): FastAPI's stock pages fetch Swagger UI and ReDoc from
a CDN and stay blank offline. The oracle is the rendered page itself (operations listed,
ReDoc's menu drawn) and the record of requests: none leaves loopback. Swagger UI's
*Authorize* button takes the operator token (the ``operatorToken`` security scheme), and
*Try it out* on ``POST /api/detections`` then gets HTTP 200 from the server.
"""

from __future__ import annotations

import json
from typing import Any

import pytest
from web_helpers import TOKEN

pytestmark = pytest.mark.timeout(240)


def test_swagger_ui_renders_offline_and_posts_with_the_token(server_factory, page: Any):
    srv = server_factory("docs")
    page.goto(f"{srv.url}/docs")
    page.wait_for_selector(".swagger-ui .opblock", timeout=60_000)
    assert page.locator(".swagger-ui .opblock").count() >= 15
    assert page.record.off_loopback() == [], page.record.off_loopback()
    # The token through the security scheme's dialog.
    page.click("button.authorize")
    page.fill(".auth-container input", TOKEN)
    page.click(".auth-btn-wrapper button.authorize")
    page.click(".auth-btn-wrapper button.btn-done")
    op = page.locator("[id^='operations-detections-'][id$='_post']").first
    op.locator(".opblock-summary").click()
    op.locator("button.try-out__btn").click()
    record = {"t": 1.0, "sensor": "cam1", "bbox": [500, 480, 540, 520], "class": "vehicle"}
    op.locator("textarea.body-param__text").fill(json.dumps({"detections": [record]}))
    with page.expect_response(lambda r: r.url.endswith("/api/detections")) as answer:
        op.locator("button.execute").click()
    response = answer.value
    assert response.status == 200, response.text()
    assert response.request.headers.get("authorization") == f"Bearer {TOKEN}"
    assert response.json()["accepted"] == 1
    assert page.record.off_loopback() == [], page.record.off_loopback()
    assert not [e for e in page.record.errors if "Failed to load" in e], page.record.errors


def test_redoc_renders_offline(server_factory, page: Any):
    srv = server_factory("redoc")
    page.goto(f"{srv.url}/redoc")
    page.wait_for_selector("redoc .menu-content", timeout=60_000)
    page.locator("h2", has_text="Ingest a batch of detections").first.wait_for(timeout=60_000)
    assert page.record.off_loopback() == [], page.record.off_loopback()
    requests = page.record.requests
    assert any(u.endswith("/vendor/redoc/redoc.standalone.js") for u in requests), requests
    assert any(u.endswith("/openapi.json") for u in requests), requests
