"""Live video in the camera panels (issue 29, item 5), in Chromium.

A red and then a blue JPEG are posted as cam1's frames: the panel shows each (its pixels
sampled from the page's own <img>), labels it with the frame's clock time, draws the box
posted for that moment over it, and falls back to the still (labelled "still") once no
new frame came for 5 s. The other cameras keep their stills throughout.
"""

from __future__ import annotations

import numpy as np
import pytest
from web_helpers import AUTH, SHOTS, open_console, wait_until

from demtrack.core.io.times import parse_iso_time
from demtrack.server.video.jpeg import encode_jpeg

pytestmark = pytest.mark.timeout(300)

T0 = parse_iso_time("2026-12-01T14:30:00Z", "t")
BOX = [600.0, 300.0, 700.0, 380.0]

# The mean RGB of the shown video frame (drawn into a canvas by the page itself).
PIXELS = """(sid) => {
  const f = window.demtrack.video.feeds.get(sid);
  if (!f || !f.img.complete || !f.img.naturalWidth) return null;
  const c = document.createElement("canvas");
  c.width = 64; c.height = 36;
  const g = c.getContext("2d");
  g.drawImage(f.img, 0, 0, 64, 36);
  const d = g.getImageData(0, 0, 64, 36).data;
  const m = [0, 0, 0];
  for (let i = 0; i < d.length; i += 4) for (let k = 0; k < 3; k += 1) m[k] += d[i + k];
  return m.map((x) => x / (d.length / 4));
}"""
FEED = """(sid) => {
  const p = window.demtrack.ui.cams.get(sid);
  const f = window.demtrack.video.feeds.get(sid);
  return {feed: p.root.dataset.feed, label: f.label.textContent, shown: f.img.style.display,
          drawn: (p.drawn || []).map((d) => d.bbox)};
}"""


def frame(rgb) -> bytes:
    img = np.full((720, 1280, 3), rgb, np.uint8)
    img[::40] = (255, 255, 255)  # a grid, so the picture is not one flat colour
    return encode_jpeg(img)


def put_frame(c, sensor, jpeg, t):
    h = {**AUTH, "Content-Type": "image/jpeg", "X-Frame-Time": repr(t)}
    r = c.put(f"/api/sensors/{sensor}/frame", content=jpeg, headers=h)
    assert r.status_code == 200 and r.json()["stored"], r.text


def close(rgb, want, tol=40):
    return rgb is not None and max(abs(a - b) for a, b in zip(rgb, want, strict=True)) < tol


def test_panel_shows_posted_frames_with_their_boxes_then_falls_back(page, server_factory):
    srv = server_factory()
    open_console(page, srv)
    assert page.evaluate(FEED, "cam1")["feed"] == "still"
    with srv.client() as c:
        rec = {"t": T0, "sensor": "cam1", "bbox": BOX, "class": "vehicle"}
        assert c.post("/api/detections", json={"detections": [rec]}).status_code == 200
        put_frame(c, "cam1", frame((220, 30, 30)), T0)
        red = wait_until(lambda: close(page.evaluate(PIXELS, "cam1"), (220, 30, 30)), 20, page=page)
        assert red, page.evaluate(PIXELS, "cam1")
        state = wait_until(lambda: (s := page.evaluate(FEED, "cam1"))["drawn"] and s, 20, page=page)
        assert state["feed"] == "video" and state["shown"] == "block"
        assert state["label"] == "video 14:30:00.0 UTC"
        assert state["drawn"] == [BOX]  # the box of the frame's moment, over the frame
        assert page.evaluate(FEED, "cam2")["feed"] == "still"
        SHOTS.mkdir(parents=True, exist_ok=True)
        page.screenshot(path=str(SHOTS / "video_red_1280.png"))
        put_frame(c, "cam1", frame((30, 30, 220)), T0 + 0.5)
        blue = wait_until(
            lambda: close(page.evaluate(PIXELS, "cam1"), (30, 30, 220)), 20, page=page
        )
        assert blue, page.evaluate(PIXELS, "cam1")
        assert page.evaluate(FEED, "cam1")["label"] == "video 14:30:00.5 UTC"
        # No box at the blue frame's moment: none drawn over it.
        assert wait_until(lambda: page.evaluate(FEED, "cam1")["drawn"] == [], 10, page=page)
    # No new frame: after 5 s the still is back, and says so.
    back = wait_until(lambda: page.evaluate(FEED, "cam1")["feed"] == "still", 20, page=page)
    assert back
    state = page.evaluate(FEED, "cam1")
    assert state["label"] == "still" and state["shown"] == "none"
    page.screenshot(path=str(SHOTS / "video_fallback_1280.png"))
    # One poll of /api/frames for all panels, and each frame fetched once.
    jpgs = [u for u in page.record.requests if u.endswith("/frame.jpg")]
    assert len(jpgs) == 2, jpgs
    assert page.record.errors == []
