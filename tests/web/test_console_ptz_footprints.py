"""A camera's footprint and field of view move on the map when its pose changes (issue 28).

In Chromium against a real server: poses are posted for ``cam1``; the page's footprint
polygon must become the server's footprint at the new pose (``GET /api/sensors/cam1``,
compared coordinate by coordinate) and the camera panel must show the new pan. Two poses
posted back to back check the rate limit's held-back message: the newest always arrives.
"""

from __future__ import annotations

import pytest
from web_helpers import SHOTS, open_console, wait_until

pytestmark = pytest.mark.timeout(400)

T0 = 1_780_000_000.0

FOOTPRINT = """(id) => {
  const poly = window.demtrack.map.coverageOf.get(id);
  return poly ? {ring: poly.getGeometry().getCoordinates()[0], wedge: poly.get('wedge')} : null;
}"""
PANEL = """(id) => {
  const p = window.demtrack.ui.cams.get(id).pose;
  return {text: p.textContent, pan: Number(p.dataset.pan)};
}"""


def _same_ring(drawn, enu, tol_m=1e-6) -> bool:
    """The page's closed ring is the server's border points (east, north), in order."""
    if drawn is None or len(drawn["ring"]) != len(enu) + 1:
        return False
    return all(
        abs(a[0] - b[0]) <= tol_m and abs(a[1] - b[1]) <= tol_m
        for a, b in zip(drawn["ring"], enu, strict=False)
    )


def test_posted_poses_move_the_footprint_wedge_and_panel(page, server_factory):
    srv = server_factory()
    with srv.client() as c:
        before = c.get("/api/sensors/cam1").json()
    open_console(page, srv)
    drawn0 = page.evaluate(FOOTPRINT, "cam1")
    assert _same_ring(drawn0, [p[:2] for p in before["footprint"]["enu"]])
    assert page.evaluate(PANEL, "cam1")["text"].startswith(f"pan {before['pan_deg']:.1f}°")
    pan0, tilt0 = before["pan_deg"], before["tilt_deg"]
    for k, (dpan, dtilt) in enumerate([(12.0, -2.0), (-9.0, -1.0), (-9.5, -1.5)]):
        pose = {"t": T0 + 0.05 * k, "pan_deg": pan0 + dpan, "tilt_deg": tilt0 + dtilt}
        with srv.client() as c:
            ack = c.post("/api/sensors/cam1/poses", json={"poses": [pose]}).json()
            assert ack["accepted"] == 1
            now = c.get("/api/sensors/cam1").json()
        assert now["pose"]["pan_deg"] == pose["pan_deg"]
        want = [p[:2] for p in now["footprint"]["enu"]]
        assert want != [p[:2] for p in before["footprint"]["enu"]]
        # the last two go within the rate limit's interval: the newest still arrives
        assert wait_until(
            lambda w=want: _same_ring(page.evaluate(FOOTPRINT, "cam1"), w), 20, page=page
        ), f"the page's footprint is not the server's at pose {k}"
        panel = page.evaluate(PANEL, "cam1")
        assert panel["pan"] == pose["pan_deg"]
        assert f"pan {pose['pan_deg']:.1f}°" in panel["text"]
        assert f"tilt {pose['tilt_deg']:.1f}°" in panel["text"]
    drawn = page.evaluate(FOOTPRINT, "cam1")
    # the wedge runs from the camera to the footprint's far corners
    assert drawn["wedge"][1] == pytest.approx(before["position_enu"][:2])
    assert drawn["wedge"][0] == pytest.approx(drawn["ring"][0])
    # the other cameras did not move
    with srv.client() as c:
        cam2 = c.get("/api/sensors/cam2").json()
    assert _same_ring(page.evaluate(FOOTPRINT, "cam2"), [p[:2] for p in cam2["footprint"]["enu"]])
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / "ptz_footprint_moved.png"))
    assert page.record.errors == []
