"""The console in clock time (issue 27, item 4): UTC with the date, local time on request.

Detections posted as a relative batch (``epoch`` 2026-12-01T14:30:00Z, ``t`` seconds
after it) are stored at their real UNIX times; the page shows them as UTC clock times
with the date, and after the UTC/local toggle as local time in the browser's zone
(Europe/Berlin here: UTC+01:00 in December). The oracle is Python's own formatting of
the same instants (``datetime`` and ``zoneinfo``), not the page's code.
"""

from __future__ import annotations

from datetime import UTC, datetime
from zoneinfo import ZoneInfo

import pytest
from web_helpers import SCENARIO, SHOTS, TOKEN, wait_until

pytestmark = pytest.mark.timeout(600)
EPOCH = "2026-12-01T14:30:00Z"
EPOCH_S = 1796135400.0
BERLIN = ZoneInfo("Europe/Berlin")
UNTIL_S = 30.0


def _clock(t_s: float, zone=UTC, digits: int = 1) -> str:
    ms = round(t_s * 1000)
    when = datetime.fromtimestamp(ms // 1000, zone)
    text = when.strftime("%Y-%m-%d %H:%M:%S")
    return text + (f".{ms % 1000:03d}"[: digits + 1] if digits else "")


def test_clock_time_with_date_utc_and_local(browser, server_factory, scenario_records):
    srv = server_factory()
    with srv.client() as c:
        for k in range(int(UNTIL_S / 5)):
            batch = [r for r in scenario_records if 5 * k <= r["t"] < 5 * (k + 1)]
            resp = c.post(
                "/api/detections",
                json={"batch_key": f"{SCENARIO}-{k}", "epoch": EPOCH, "detections": batch},
            )
            assert resp.status_code == 200 and resp.json()["skipped"] == 0, resp.text
        stored = c.get("/api/detections", params={"limit": 1}).json()[0]
        # the API's own answer: real UNIX seconds, and the ISO time beside them
        assert stored["t"] >= EPOCH_S and stored["time_utc"].startswith("2026-12-01T14:30:")
        window = c.get(
            "/api/detections",
            params={"t_from": "2026-12-01T15:30:05+01:00", "t_to": EPOCH_S + 6, "limit": 10},
        ).json()
        assert window and all(EPOCH_S + 5 <= d["t"] <= EPOCH_S + 6 for d in window)
        bad = c.get("/api/detections", params={"t_from": "2026-12-01T14:30:05"})
        assert bad.status_code == 422 and "t_from" in bad.json()["detail"]
        assert "no zone" in bad.json()["detail"] and "\n" not in bad.json()["detail"]

    context = browser.new_context(
        viewport={"width": 1280, "height": 800}, timezone_id="Europe/Berlin"
    )
    pg = context.new_page()
    errors: list[str] = []
    pg.on("pageerror", lambda e: errors.append(str(e)))
    try:
        pg.goto(f"{srv.url}/?token={TOKEN}")
        pg.wait_for_selector("body[data-ready='1']", timeout=60_000)
        pg.evaluate("window.demtrack.timeline.pause()")
        pg.evaluate(f"window.demtrack.timeline.seek({EPOCH_S + 12.3})")
        t_max = pg.evaluate("window.demtrack.store.tMax")
        assert EPOCH_S + 20 < t_max < EPOCH_S + UNTIL_S

        def label() -> tuple[str, str]:  # (clock line, date line)
            return pg.text_content("#t-clock"), pg.text_content("#t-date")

        def want(zone, name):
            shown, newest = _clock(EPOCH_S + 12.3, zone), _clock(t_max, zone, 0)
            return f"{shown[11:]} {name}", f"{shown[:10]} · newest {newest[11:]}"

        wait_until(lambda: label() == want(UTC, "UTC"), timeout_s=20, page=pg)
        assert label()[0] == "14:30:12.3 UTC" and label()[1].startswith(
            "2026-12-01 · newest 14:30:"
        )
        assert pg.text_content("#clock-zone") == "UTC"
        rows = pg.locator("#event-list [data-t]")
        wait_until(lambda: rows.count() > 0, timeout_s=30, page=pg)
        t_row = float(rows.first.get_attribute("data-t"))
        assert rows.first.get_attribute("title").endswith(f"— {_clock(t_row)} UTC")
        SHOTS.mkdir(parents=True, exist_ok=True)
        pg.screenshot(path=str(SHOTS / "console_clock_utc.png"))

        pg.click("#clock-zone")
        wait_until(lambda: label() == want(BERLIN, "local"), timeout_s=20, page=pg)
        assert label()[0] == "15:30:12.3 local"
        assert "local (UTC+01:00)" in pg.get_attribute("#t-label", "title")
        wait_until(
            lambda: rows.first.get_attribute("title").endswith(
                f"— {_clock(float(rows.first.get_attribute('data-t')), BERLIN)} local (UTC+01:00)"
            ),
            timeout_s=30,
            page=pg,
        )
        pg.screenshot(path=str(SHOTS / "console_clock_local.png"))
        # the choice is kept across a reload, and toggles back
        pg.reload()
        pg.wait_for_selector("body[data-ready='1']", timeout=60_000)
        assert pg.text_content("#clock-zone") == "local"
        pg.click("#clock-zone")
        assert pg.text_content("#clock-zone") == "UTC"
        assert not errors
    finally:
        context.close()
