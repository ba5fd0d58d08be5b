"""The 3D view needs the operator token, has a legend and hides the 2D layer controls
(issue 26, item 9): a real ``demtrack serve --3d``, Chromium and viser's own client.

The console page admits its follow session with its token (``PUT /api/scene3d/session``)
and its iframe's viser client is then served; a WebSocket to the viser server that names
no admitted session is closed with 4401 before it gets anything.
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import urlsplit

import pytest
from web_helpers import AUTH, SHOTS, Server, free_port, open_console, post_until, wait_until

from demtrack.server.scene3d import style

pytestmark = pytest.mark.timeout(400)


def test_3d_view_needs_the_token_and_shows_a_legend(
    page, sample_site_dir: Path, tmp_path: Path, scenario_records
):
    import viser
    from websockets.exceptions import ConnectionClosed
    from websockets.sync.client import connect

    srv = Server(
        sample_site_dir,
        tmp_path / "s3d.sqlite3",
        free_port(),
        extra_args=("--3d", "--viser-port", "0"),
    ).start()
    try:
        with srv.client() as c:
            post_until(c, scenario_records, -1.0, 12.0)
            open_console(page, srv)
            viser_url = page.evaluate("window.demtrack.ui.viserUrl")
            port = urlsplit(viser_url).port
            sid = page.evaluate("window.demtrack.ui.follow3d.session")
            # Without the token, the API refuses to admit a session.
            import httpx2 as httpx

            r = httpx.put(f"{srv.url}/api/scene3d/session", json={"session": "f" * 32}, timeout=30)
            assert r.status_code == 401
            # A viser client with no admitted session (viser's root, a made-up session):
            # closed with 4401, nothing sent to it.
            for path in ("/", f"/follow/{'e' * 32}"):
                ws = connect(
                    f"ws://127.0.0.1:{port}{path}", subprotocols=[f"viser-v{viser.__version__}"]
                )
                try:
                    with pytest.raises(ConnectionClosed) as closed:
                        ws.recv(timeout=10)
                    assert closed.value.rcvd.code == 4401
                    assert "operator token" in closed.value.rcvd.reason
                finally:
                    ws.close()
            # The console page admitted its own session at start-up, with its token.
            assert page.evaluate("window.demtrack.ui.follow3d.admitted") is True
            # The 3D tab: its viser client connects and is served (listed by the scene).
            assert page.locator("#pane-layers").is_visible()
            page.locator("#tab-3d").click()
            assert page.locator("#pane-layers").is_hidden()  # 2D layer controls hidden
            legend = page.locator("#legend-3d")
            assert legend.is_visible()
            items = page.evaluate(
                """[...document.querySelectorAll('#legend-3d span > span')].map((s) =>
                [s.parentElement.textContent, getComputedStyle(s).borderTopColor,
                 getComputedStyle(s).backgroundColor])"""
            )
            texts = [t for t, _, _ in items]
            assert any("vehicle track" in t for t in texts) and any(
                "human track" in t for t in texts
            )

            def rgb(hexc: str) -> str:
                r_, g_, b_ = style.hex_colour(hexc)
                return f"rgb({r_}, {g_}, {b_})"

            colours = {t: (border, bg) for t, border, bg in items}
            veh = next(v for t, v in colours.items() if t.startswith("vehicle track"))
            assert rgb(style.CLASS_COLOURS["vehicle"]) in veh
            for k, sensor in enumerate(sorted(s["id"] for s in c.get("/api/sensors").json())):
                entry = next(v for t, v in colours.items() if t.startswith(f"{sensor}:"))
                assert rgb(style.SENSOR_COLOURS[k]) in entry
            hit = next(v for t, v in colours.items() if t.startswith("terrain hits"))
            assert rgb(style.HIT_COLOUR) in hit
            src = page.evaluate("document.querySelector('#viser').src")
            assert src.endswith(f"%2Ffollow%2F{sid}")
            assert wait_until(
                lambda: c.get("/api/scene3d/follow", params={"session": sid}, headers=AUTH).json()[
                    "clients"
                ],
                180,
                page=page,
            ), "the console's viser client was not admitted"
            page.wait_for_timeout(2000)
            SHOTS.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(SHOTS / "scene3d_legend_1280.png"))
            everyone = c.get("/api/scene3d/follow").json()["clients"]
            assert [k["session"] for k in everyone] == [sid]  # only the admitted one
            page.locator("#tab-map").click()
            assert page.locator("#pane-layers").is_visible()
        assert page.record.errors == []
    finally:
        srv.stop()
