"""The ONVIF PTZ adapter against a loopback ONVIF PTZ service (real HTTP, real SOAP)."""

from __future__ import annotations

import math

import pytest
from onvif_service import OnvifPtzService

from demtrack.core.camera.head_motion import HeadState, SlewLimits, time_to_reach
from demtrack.server.heads.adapter import HeadAdapter, HeadAdapterError
from demtrack.server.heads.onvif import OnvifHead, OnvifMapping

T0 = 1.8e9


class Clock:
    def __init__(self, t: float = T0) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def device():
    clock = Clock()
    with OnvifPtzService(clock=clock) as svc:
        svc.clock_ref = clock
        yield svc


def head_for(svc: OnvifPtzService, **kw) -> OnvifHead:
    return OnvifHead(svc.url, svc.profile, OnvifMapping(), timeout_s=2.0, **kw)


def test_it_is_a_head_adapter(device):
    assert isinstance(head_for(device), HeadAdapter)


def test_absolute_move_arrives_in_the_time_the_kinematics_promise(device):
    head = head_for(device)
    s0 = head.status()
    assert (s0.t_s, s0.pan_deg, s0.tilt_deg, s0.moving) == (pytest.approx(T0), 0.0, 0.0, False)
    assert s0.hfov_deg == pytest.approx(60.0)
    head.absolute_move(-120.0, -20.0, 10.0)
    t_reach = time_to_reach(HeadState(T0, 0, 0, 60.0), -120.0, -20.0, 10.0, SlewLimits())
    device.clock_ref.t = T0 + t_reach / 2
    mid = head.status()
    assert mid.moving and mid.pan_deg < 0.0
    device.clock_ref.t = T0 + t_reach + 0.01
    end = head.status()
    assert not end.moving
    # Through the normalised spaces and back: float-exact up to the x/y/zoom rounding.
    assert end.pan_deg == pytest.approx(-120.0, abs=1e-9)
    assert end.tilt_deg == pytest.approx(-20.0, abs=1e-9)
    assert end.hfov_deg == pytest.approx(10.0, abs=1e-9)
    assert end.t_s == pytest.approx(T0 + t_reach + 0.01, abs=1e-5)  # the device's UtcTime
    assert device.requests == ["GetStatus", "AbsoluteMove", "GetStatus", "GetStatus"]


def test_continuous_move_and_stop(device):
    head = head_for(device)
    head.continuous_move(30.0, -20.0, 0.0)  # half of 60 deg/s, half of 40 deg/s
    device.clock_ref.t = T0 + 2.0
    s = head.status()
    # ramp 0.25 s (30 deg/s at 120 deg/s^2) then 1.75 s at 30 deg/s: 3.75 + 52.5 deg
    assert s.pan_deg == pytest.approx(0.5 * 30 * 0.25 + 30 * 1.75, abs=1e-9)
    assert s.tilt_deg == pytest.approx(-(0.5 * 20 * (20 / 120) + 20 * (2 - 20 / 120)), abs=1e-9)
    assert s.moving
    head.stop()
    device.clock_ref.t = T0 + 3.0
    assert not head.status().moving


def test_digest_credentials(tmp_path):
    clock = Clock()
    with OnvifPtzService(clock=clock, user="admin", password="s3cret") as svc:
        assert head_for(svc, user="admin", password="s3cret").status().pan_deg == 0.0
        with pytest.raises(HeadAdapterError, match="NotAuthorized"):
            head_for(svc, user="admin", password="wrong").status()
        with pytest.raises(HeadAdapterError, match="NotAuthorized"):
            head_for(svc).status()


def test_faults_timeouts_and_dead_ports_are_one_clear_error(device):
    head = head_for(device)
    device.fault_next = True
    with pytest.raises(HeadAdapterError, match=r"AbsoluteMove: SOAP fault .*ter:Action"):
        head.absolute_move(10.0, 0.0, None)
    wrong_profile = OnvifHead(device.url, "nope", timeout_s=2.0)
    with pytest.raises(HeadAdapterError, match="InvalidArgVal"):
        wrong_profile.status()
    device.hang_s = 1.0
    slow = OnvifHead(device.url, device.profile, timeout_s=0.2)
    with pytest.raises(HeadAdapterError, match=r"GetStatus: no answer within 0.2 s"):
        slow.status()
    device.hang_s = 0.0
    dead = OnvifHead("http://127.0.0.1:9/onvif", "p", timeout_s=0.5)
    with pytest.raises(HeadAdapterError, match="ONVIF head http://127.0.0.1:9/onvif GetStatus"):
        dead.status()


@pytest.mark.parametrize("scale", ["focal", "hfov"])
def test_mapping_round_trips(scale):
    m = OnvifMapping(pan_range_deg=(-170.0, 170.0), tilt_range_deg=(-45.0, 45.0), zoom_scale=scale)
    for pan in (-170.0, -30.0, 0.0, 99.5, 170.0):
        assert m.x_to_pan(m.pan_to_x(pan)) == pytest.approx(pan, abs=1e-12)
    for tilt in (-45.0, 0.0, 12.5):
        assert m.y_to_tilt(m.tilt_to_y(tilt)) == pytest.approx(tilt, abs=1e-12)
    for hfov in (60.0, 30.0, 3.0):
        assert m.zoom_to_hfov(m.hfov_to_zoom(hfov)) == pytest.approx(hfov, abs=1e-9)
    assert (m.hfov_to_zoom(60.0), m.hfov_to_zoom(3.0)) == pytest.approx((0.0, 1.0))
    assert m.pan_to_x(-170.0) == -1.0 and m.pan_to_x(180.0) == 1.0  # clipped
    full = OnvifMapping()
    assert full.pan_to_x(-180.0) == -1.0 and full.x_to_pan(1.0) == 180.0
    # Focal-linear zoom: halfway in zoom is halfway in 1/tan(hfov/2), not in degrees.
    if scale == "focal":
        k = (1 / math.tan(math.radians(30)) + 1 / math.tan(math.radians(1.5))) / 2
        assert m.zoom_to_hfov(0.5) == pytest.approx(math.degrees(2 * math.atan(1 / k)))
    with pytest.raises(HeadAdapterError, match="zoom_scale"):
        OnvifMapping(zoom_scale="log")
