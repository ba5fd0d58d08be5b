"""Active heads from site.json (adapters, limits, refusals), the simulated head, the journal."""

from __future__ import annotations

import math

import pytest
from heads_helpers import T0, Clock, active_site
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.camera.head_motion import SlewLimits
from demtrack.core.errors import SiteError
from demtrack.core.site.folder import load_site
from demtrack.server.heads.config import active_head_configs, build_adapter
from demtrack.server.heads.journal import HeadJournal
from demtrack.server.heads.onvif import OnvifHead, OnvifMapping
from demtrack.server.heads.simulated import SimulatedHead


def site_with(sample_site_dir, tmp_path, entries):
    return load_site(active_site(sample_site_dir, tmp_path / "site", entries))


def test_active_sensors_get_their_limits_and_adapters(sample_site_dir, tmp_path, monkeypatch):
    monkeypatch.setenv("CAM3_PW", "pw")
    onvif = {"kind": "onvif", "url": "http://10.0.0.9/onvif/ptz", "profile": "p1",
             "user": "admin", "password_env": "CAM3_PW", "tilt_range_deg": [-45, 45]}  # fmt: skip
    site = site_with(
        sample_site_dir,
        tmp_path,
        {
            "cam1": {"active": True, "slew_limits": {"pan_rate_deg_s": 30}},
            "cam2": {"active": True, "head_adapter": {"kind": "external"}},
            "cam3": {"active": True, "head_adapter": onvif},
        },
    )
    configs = active_head_configs(site)
    assert [c.sensor_id for c in configs] == ["cam1", "cam3"]  # cam2's gateway posts poses
    assert configs[0].limits == SlewLimits(pan_rate_deg_s=30)
    sim = build_adapter(site, configs[0], Clock())
    assert isinstance(sim, SimulatedHead)
    s = sim.status()
    assert (s.pan_deg, s.tilt_deg) == pytest.approx(
        (site.sensor("cam1").pan_deg, site.sensor("cam1").tilt_deg)
    )
    head = build_adapter(site, configs[1])
    assert isinstance(head, OnvifHead)
    assert (head.url, head.profile, head.user, head.password) == (
        "http://10.0.0.9/onvif/ptz", "p1", "admin", "pw",
    )  # fmt: skip
    assert head.mapping == OnvifMapping(tilt_range_deg=(-45.0, 45.0))


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        ({"active": True, "head_adapter": {"kind": "visca"}}, "kind must be one of sim, onvif"),
        ({"active": True, "head_adapter": {"kind": "onvif", "url": "x"}}, "needs 'url' and"),
        (
            {
                "active": True,
                "head_adapter": {
                    "kind": "onvif",
                    "url": "http://h",
                    "profile": "p",
                    "password_env": "NOT_SET_ANYWHERE_42",
                },
            },
            "NOT_SET_ANYWHERE_42 is not set",
        ),  # fmt: skip
        (
            {"active": True, "head_adapter": {"kind": "onvif", "url": "ftp://h", "profile": "p"}},
            "must be http",
        ),
    ],
)
def test_bad_head_entries_are_one_line(sample_site_dir, tmp_path, entry, message):
    site = site_with(sample_site_dir, tmp_path, {"cam1": entry})
    with pytest.raises(SiteError, match=message) as err:
        for c in active_head_configs(site):
            build_adapter(site, c)
    assert "cam1" in str(err.value) and "\n" not in str(err.value)


def test_simulated_head_reads_do_not_change_where_it_goes():
    # Polled often or once, the head is where the kinematics put it (exact integration).
    a_clock, b_clock = Clock(), Clock()
    a = SimulatedHead(SlewLimits(), 0.0, 0.0, 50.0, clock=a_clock)
    b = SimulatedHead(SlewLimits(), 0.0, 0.0, 50.0, clock=b_clock)
    a.absolute_move(120.0, -30.0, 10.0)
    b.absolute_move(120.0, -30.0, 10.0)
    for k in range(1, 31):
        a_clock.t = T0 + 0.1 * k
        a.status()
    b_clock.t = T0 + 3.0
    sa, sb = a.status(), b.status()
    assert (sa.pan_deg, sa.tilt_deg, sa.hfov_deg) == pytest.approx(
        (sb.pan_deg, sb.tilt_deg, sb.hfov_deg), abs=1e-9
    )
    assert sa.moving  # zoom takes 4 s at 10 deg/s: still going
    a_clock.t = b_clock.t = T0 + 10.0
    assert not a.status().moving
    a.continuous_move(0.0, 0.0, -5.0)
    a_clock.t += 1.0
    assert a.status().hfov_deg == pytest.approx(5.0) and a.status().moving
    a.stop()
    a_clock.t += 1.0
    assert not a.status().moving


def test_journal_rows_and_torn_lines(tmp_path):
    j = HeadJournal(tmp_path / "j.jsonl")
    j.append({"t_s": 1.0, "sensor_id": "cam1", "mode": "slew", "pan_deg": 3.0})
    j.append({"t_s": 2.0, "sensor_id": "cam3", "mode": "follow", "track_id": 4})
    j.append({"t_s": 3.0, "sensor_id": "cam1", "mode": "idle"})
    with open(j.path, "a", encoding="utf-8") as fh:
        fh.write('[1, 2]\n{"t_s": 4, "sensor')
    assert [r["mode"] for r in j.rows()] == ["slew", "follow", "idle"]
    assert {k: v["mode"] for k, v in j.last_by_sensor().items()} == {
        "cam1": "idle",
        "cam3": "follow",
    }
    with pytest.raises(ValueError):
        j.append({"t_s": math.nan, "sensor_id": "cam1", "mode": "idle"})  # never a NaN line
    assert HeadJournal(None).rows() == []


@settings(max_examples=200, deadline=None)
@given(
    lo=st.floats(-180, 0), span=st.floats(10, 360), x=st.floats(-1, 1),
    wide=st.floats(20, 120), tele=st.floats(1, 19), z=st.floats(0, 1),
    scale=st.sampled_from(["focal", "hfov"]),
)  # fmt: skip
def test_mapping_inverts_inside_its_ranges(lo, span, x, wide, tele, z, scale):
    m = OnvifMapping(pan_range_deg=(lo, lo + span), tilt_range_deg=(lo / 2, lo / 2 + span / 4),
                     hfov_deg=(wide, tele), zoom_scale=scale)  # fmt: skip
    pan = m.x_to_pan(x)
    if span < 360:  # a full turn has two x for 180 deg
        assert m.pan_to_x(pan) == pytest.approx(x, abs=1e-9)
    assert m.tilt_to_y(m.y_to_tilt(x)) == pytest.approx(x, abs=1e-9)
    h = m.zoom_to_hfov(z)
    assert tele - 1e-9 <= h <= wide + 1e-9
    assert m.hfov_to_zoom(h) == pytest.approx(z, abs=1e-9)
