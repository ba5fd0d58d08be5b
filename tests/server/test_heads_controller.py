"""The head controller on the sample site: follow and hand-off through two loopback ONVIF heads.

The target is the ``vehicle-run`` scenario's true path, handed to the controller as a live
track (:class:`heads_helpers.ScriptedTracks`); the heads are real ONVIF PTZ services on
loopback (real HTTP and SOAP), moving under the kinematic limits on a shared test clock.
The oracle of "follows" is the camera model: the target, projected through the head's
*reported* pan and tilt, lies near the image centre. The oracle of "hands off" is the
order of what the second device received and where it pointed when the target arrived.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from heads_helpers import T0, Clock, ScriptedTracks, active_site
from onvif_service import OnvifPtzService

from demtrack.core.camera.pantilt import wrap_deg
from demtrack.core.errors import NotFoundError, UnknownSensorError
from demtrack.core.site.folder import load_site
from demtrack.core.visibility.viewshed import target_visible_fraction
from demtrack.server.heads.aim import AimError, aim_pan_tilt
from demtrack.server.heads.config import active_head_configs, build_adapter
from demtrack.server.heads.controller import HeadController, HeadNotActiveError, HeadUnit
from demtrack.server.heads.journal import HeadJournal


@pytest.fixture(scope="module")
def truth(sample_site_dir):
    from demtrack.samplesite.scenarios import make_scenario

    return make_scenario(load_site(sample_site_dir), "vehicle-run").truths[0]


def onvif_entry(svc: OnvifPtzService) -> dict:
    return {
        "active": True,
        "head_adapter": {"kind": "onvif", "url": svc.url, "profile": svc.profile, "timeout_s": 2},
    }


def controller(site, clock, tracks, journal=None) -> HeadController:
    units = [
        HeadUnit(c.sensor_id, build_adapter(site, c, clock), c.limits, c.adapter["kind"])
        for c in active_head_configs(site)
    ]
    ctl = HeadController(site, units, tracks, None, journal, period_s=0.1, clock=clock)
    ctl.planner.clock = clock
    return ctl


def centred(site, sensor_id, status, p_enu) -> float:
    """Horizontal offset of the target's middle from the image centre, share of the width."""
    sensor = site.sensor(sensor_id)
    cam = sensor.head.camera_at(status.pan_deg, status.tilt_deg)
    uv = cam.project(np.asarray(p_enu, float)[None, :] + [0.0, 0.0, 0.75])[0]
    return abs(float(uv[0]) - sensor.head.intrinsics.cx) / sensor.head.intrinsics.width


def test_onvif_heads_follow_and_hand_off(sample_site_dir, tmp_path, truth):
    clock = Clock()
    site1 = load_site(sample_site_dir)
    # cam3 sees the start of the run and loses its sight line about 42 s in; cam1 can see
    # the road from about 28 s, but starts looking the other way. cam2 (fixed) is left
    # out, so the only way to keep the target is the hand-off.
    pan1 = float(wrap_deg(site1.sensor("cam1").pan_deg + 180.0))
    with (
        OnvifPtzService(clock=clock, pan_deg=site1.sensor("cam3").pan_deg) as dev3,
        OnvifPtzService(clock=clock, pan_deg=pan1, profile="cam1_main") as dev1,
    ):
        site = load_site(
            active_site(
                sample_site_dir,
                tmp_path / "site",
                {"cam3": onvif_entry(dev3), "cam1": onvif_entry(dev1), "cam2": None},
            )
        )
        tracks = ScriptedTracks(truth, clock, end_s=60.0)
        journal = HeadJournal(tmp_path / "heads.jsonl")
        ctl = controller(site, clock, tracks, journal)
        assert {u: ctl.units[u].kind for u in ctl.units} == {"cam1": "onvif", "cam3": "onvif"}
        clock.t = T0 + 1.0
        ctl.tick()
        ctl.follow("cam3", 7)
        offsets3, offsets1, modes, best = [], [], [], []
        handoff_tick = None
        for k in range(11, 600):  # 1 s .. 60 s at 10 Hz
            clock.t = T0 + 0.1 * k
            n_before = len(dev1.requests)
            ctl.tick()
            t_rel = 0.1 * k
            p = truth.at(np.array([t_rel]))[0]
            modes.append((t_rel, ctl.units["cam3"].mode, ctl.units["cam1"].mode))
            if handoff_tick is None and ctl.units["cam1"].mode == "handoff":
                handoff_tick = k
                entry_t = ctl.units["cam1"].target["entry_t_s"] - T0
                idle_requests, handoff_requests = dev1.requests[:n_before], dev1.requests[n_before:]
            off = {
                sid: centred(site, sid, ctl.units[sid].status, p)
                for sid in ("cam1", "cam3")
                if ctl.units[sid].mode == "follow"
            }
            if 3.0 < t_rel < 45.0:
                best.append(min(off.values(), default=1.0))
            if handoff_tick is None and "cam3" in off and t_rel > 3.0:
                offsets3.append(off["cam3"])
            if handoff_tick is not None and entry_t + 1.5 < t_rel < entry_t + 4.0:
                offsets1.append(off.get("cam1", 1.0))
        assert handoff_tick is not None, modes[::20]
        # cam3 followed: the target stayed near its image centre until the hand-off.
        assert len(offsets3) > 100 and max(offsets3) < 0.05
        # The first hand-off came before the target reached cam1, with time for the slew.
        (frm, to, tid, entry_in_s, slew_s) = ctl.planner.history[0]
        assert (frm, to, tid) == ("cam3", "cam1", 7)
        assert slew_s > 1.0 and entry_in_s >= slew_s  # it had to turn round, in time
        assert set(idle_requests) == {"GetStatus"}  # idle until then: only polled
        assert "AbsoluteMove" in handoff_requests  # slewed ahead at the hand-off
        # cam1 then had it near its image centre from its first seconds.
        assert len(offsets1) == 25 and max(offsets1) < 0.05
        # Between them the target was centred (within 5 % of the width) almost all the
        # time: hand-offs back and forth where each loses its sight line for a while.
        assert np.mean(np.array(best) < 0.05) > 0.9
        assert all(a != b for a, b, *_ in ctl.planner.history)
        rows = journal.rows()
        assert [(r["sensor_id"], r["mode"]) for r in rows][:3] == [
            ("cam3", "follow"),
            ("cam1", "handoff"),
            ("cam3", "follow"),
        ]
        assert rows[2]["handed_to"] == "cam1"


def test_slew_look_release_and_refusals(sample_site_dir, tmp_path):
    clock = Clock()
    site = load_site(active_site(sample_site_dir, tmp_path / "site", {"cam1": {"active": True}}))
    ctl = controller(site, clock, None)
    ctl.tick()
    info = ctl.slew("cam1", 10.0, -5.0, 30.0)
    assert info["mode"] == "slew" and info["target"]["pan_deg"] == 10.0
    clock.t += 10.0
    ctl.tick()
    st = ctl.units["cam1"].status
    assert (st.pan_deg, st.tilt_deg, st.hfov_deg) == pytest.approx((10.0, -5.0, 30.0))
    # Ground points near the site's middle that cam1 sees, and one it cannot see.
    sensor = site.sensor("cam1")
    grid = np.stack(np.meshgrid(np.arange(-150, 150, 10.0), np.arange(-150, 150, 10.0)), -1)
    xy = grid.reshape(-1, 2)
    z = site.dem.sample(xy[:, 0], xy[:, 1])
    pts = np.column_stack([xy, z])[np.isfinite(z)]
    seen = target_visible_fraction(
        site.dem, sensor.camera, pts, 1.5, in_view=False, max_range_m=5000
    )
    visible, hidden = pts[seen >= 0.9][0], pts[seen == 0.0][0]
    info = ctl.look("cam1", float(visible[0]), float(visible[1]), None)
    pan, tilt = aim_pan_tilt(sensor, visible + [0.0, 0.0, 1.0])  # 1 m up: what stands there
    assert info["mode"] == "look"
    assert (info["target"]["pan_deg"], info["target"]["tilt_deg"]) == pytest.approx((pan, tilt))
    with pytest.raises(AimError, match="blocked by terrain"):
        ctl.look("cam1", float(hidden[0]), float(hidden[1]), None)
    with pytest.raises(AimError, match="off the DEM"):
        ctl.look("cam1", 1e6, 0.0, None)
    with pytest.raises(UnknownSensorError):
        ctl.info("nope")
    with pytest.raises(HeadNotActiveError, match="fixed mount"):
        ctl.slew("cam2", 0.0, 0.0, None)
    with pytest.raises(NotFoundError, match="no live track 3"):
        ctl.follow("cam1", 3)
    assert ctl.release("cam1")["mode"] == "idle"


def test_journal_restores_slews_and_follows_after_a_restart(sample_site_dir, tmp_path, truth):
    clock = Clock(T0 + 5.0)
    site = load_site(
        active_site(
            sample_site_dir, tmp_path / "site", {"cam1": {"active": True}, "cam3": {"active": True}}
        )
    )
    tracks = ScriptedTracks(truth, clock)
    path = tmp_path / "heads.jsonl"
    first = controller(site, clock, tracks, HeadJournal(path))
    first.tick()
    first.slew("cam1", -40.0, -12.0, None)
    first.follow("cam3", 7)
    before = {sid: (u.mode, u.target) for sid, u in first.units.items()}
    with open(path, "a", encoding="utf-8") as fh:
        fh.write('{"t_s": 1, "sensor_id": "cam1", "mo')  # a torn last line: skipped
    second = controller(site, clock, tracks, HeadJournal(path))
    second.restore()
    assert {sid: (u.mode, u.target) for sid, u in second.units.items()} == before
    clock.t += 5.0
    second.tick()
    st = second.units["cam1"].status
    assert (st.pan_deg, st.tilt_deg) == pytest.approx((-40.0, -12.0))
    assert second.units["cam3"].last_aim is not None  # following again
    lines = path.read_text().splitlines()
    assert json.loads(lines[0])["mode"] == "slew"
