from __future__ import annotations

import math

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.camera.head_motion import (
    HeadCommand,
    HeadState,
    SlewLimits,
    step,
    time_to_reach,
)
from demtrack.core.errors import CameraError

LIMITS = SlewLimits()  # 60 deg/s pan, 40 deg/s tilt, 120 deg/s^2, 10 deg/s zoom
T0 = 1.8e9  # a real clock time: nothing may treat t as small


def wrap(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def run(state, command, dt, n, limits=LIMITS):
    out = [state]
    for _ in range(n):
        out.append(step(out[-1], command, dt, limits))
    return out


def trapezoid_time(d: float, vmax: float, accel: float) -> float:
    """Rest-to-rest time over distance d: the textbook trapezoid or triangle."""
    d = abs(d)
    if d >= vmax * vmax / accel:
        return vmax / accel + d / vmax
    return 2.0 * math.sqrt(d / accel)


@pytest.mark.parametrize("d", [0.5, 10.0, 30.0, 90.0, 179.0])
def test_rest_to_rest_pan_time_is_the_textbook_profile(d):
    start = HeadState(T0, 0.0, 0.0, 30.0)
    expected = trapezoid_time(d, 60.0, 120.0)
    assert time_to_reach(start, d, 0.0, None, LIMITS) == pytest.approx(expected, rel=1e-12)
    # Halfway through the time the head is halfway (the profile is symmetric) ...
    half = step(start, HeadCommand(pan_deg=d, tilt_deg=0.0), expected / 2, LIMITS)
    assert half.pan_deg == pytest.approx(d / 2, abs=1e-9)
    # ... at its peak rate: the rate limit, or a*T/2 on a triangle.
    assert half.pan_rate_deg_s == pytest.approx(min(60.0, 120.0 * expected / 2), rel=1e-12)
    end = step(start, HeadCommand(pan_deg=d, tilt_deg=0.0), expected, LIMITS)
    assert (end.pan_deg, end.pan_rate_deg_s) == (d, 0.0)


@pytest.mark.parametrize("d", [1.0, 13.0, 35.0, -80.0])
def test_rest_to_rest_tilt_time(d):
    start = HeadState(T0, 0.0, -10.0, 30.0)
    got = time_to_reach(start, 0.0, -10.0 + d, None, LIMITS)
    assert got == pytest.approx(trapezoid_time(d, 40.0, 120.0), rel=1e-12)


@pytest.mark.parametrize(
    ("v0", "d", "expected"),
    [
        # toward the target: ramp 30 -> 60 (0.25 s, 11.25 deg), brake (0.5 s, 15 deg), cruise
        (30.0, 90.0, 0.25 + 0.5 + (90.0 - 26.25) / 60.0),
        # away from it: brake 0.25 s (3.75 deg the wrong way), then 93.75 deg from rest
        (-30.0, 90.0, 0.25 + trapezoid_time(93.75, 60.0, 120.0)),
        # faster than the limit: slow to 60 (0.25 s, 18.75 deg), cruise, brake
        (90.0, 200.0, 0.25 + 0.5 + (200.0 - 33.75) / 60.0),
        # too close to stop: brake over 15 deg (0.5 s), come back 10 deg from rest
        (60.0, 5.0, 0.5 + trapezoid_time(10.0, 60.0, 120.0)),
        # exactly the braking distance: brake only
        (60.0, 15.0, 0.5),
    ],
)
def test_moving_start_times(v0, d, expected):
    start = HeadState(T0, 0.0, 0.0, 30.0, pan_rate_deg_s=v0)
    assert time_to_reach(start, d, 0.0, None, LIMITS) == pytest.approx(expected, rel=1e-12)
    end = step(start, HeadCommand(pan_deg=d, tilt_deg=0.0), expected, LIMITS)
    assert (end.pan_deg, end.pan_rate_deg_s) == (wrap(d), 0.0)


def test_pan_goes_the_short_way_round():
    start = HeadState(T0, 170.0, 0.0, 30.0)
    assert time_to_reach(start, -170.0, 0.0, None, LIMITS) == pytest.approx(
        trapezoid_time(20.0, 60.0, 120.0)
    )
    states = run(start, HeadCommand(pan_deg=-170.0), 0.05, 20)
    assert all(s.pan_rate_deg_s >= 0.0 for s in states)  # always clockwise, across 180
    assert states[-1].pan_deg == -170.0
    assert all(-180.0 < s.pan_deg <= 180.0 for s in states)


def test_pan_copy_is_chosen_from_the_stopping_point():
    # Turning clockwise at 60 deg/s the head stops 15 deg on; a target 170 deg
    # anticlockwise of it is 175 deg clockwise of the stopping point: keep going.
    start = HeadState(T0, 0.0, 0.0, 30.0, pan_rate_deg_s=60.0)
    states = run(start, HeadCommand(pan_deg=-170.0), 0.05, 80)
    assert all(s.pan_rate_deg_s >= 0.0 for s in states)
    assert states[-1].pan_deg == -170.0


def test_tilt_and_hfov_clamp_to_limits():
    start = HeadState(T0, 0.0, 0.0, 30.0)
    end = run(start, HeadCommand(pan_deg=0.0, tilt_deg=80.0, hfov_deg=1.0), 0.1, 40)[-1]
    assert (end.tilt_deg, end.hfov_deg) == (30.0, 3.0)
    assert time_to_reach(start, 0.0, 80.0, 1.0, LIMITS) == pytest.approx(27.0 / 10.0)


def test_zoom_moves_at_its_rate():
    start = HeadState(T0, 0.0, 0.0, 30.0)
    s = step(start, HeadCommand(hfov_deg=20.0), 0.5, LIMITS)
    assert s.hfov_deg == pytest.approx(25.0)
    assert time_to_reach(start, 0.0, 0.0, 20.0, LIMITS) == pytest.approx(1.0)


def test_velocity_command_ramps_then_holds_and_tilt_stops_at_its_limit():
    start = HeadState(T0, 0.0, 20.0, 30.0)
    command = HeadCommand(pan_rate_deg_s=-100.0, tilt_rate_deg_s=25.0, zoom_rate_deg_s=4.0)
    states = run(start, command, 0.05, 60)
    assert states[10].pan_rate_deg_s == pytest.approx(-60.0)  # clamped to the limit, 0.5 s
    assert states[-1].pan_rate_deg_s == pytest.approx(-60.0)
    assert max(s.tilt_deg for s in states) <= 30.0  # braked in time
    assert states[-1].tilt_deg == 30.0 and states[-1].tilt_rate_deg_s == 0.0
    assert states[-1].hfov_deg == pytest.approx(42.0)
    stopped = run(states[-1], None, 0.05, 20)[-1]
    assert stopped.pan_rate_deg_s == 0.0 and stopped.tilt_rate_deg_s == 0.0


def test_limits_round_trip_and_refuse_bad_values():
    limits = SlewLimits(pan_rate_deg_s=90.0, hfov_min_deg=2.0)
    assert SlewLimits.from_dict(limits.to_dict()) == limits
    assert SlewLimits.from_dict(None) == SlewLimits()
    assert SlewLimits.from_dict({"accel_deg_s2": 50}).accel_deg_s2 == 50.0
    with pytest.raises(CameraError, match="unknown keys \\['pan_rate'\\]"):
        SlewLimits.from_dict({"pan_rate": 3})
    with pytest.raises(CameraError, match="accel_deg_s2 must be positive"):
        SlewLimits(accel_deg_s2=0.0)
    with pytest.raises(CameraError, match="tilt_min_deg"):
        SlewLimits(tilt_min_deg=10.0, tilt_max_deg=0.0)
    with pytest.raises(CameraError, match="finite"):
        SlewLimits(pan_rate_deg_s=math.nan)
    with pytest.raises(CameraError, match="not both"):
        HeadCommand(pan_deg=1.0, tilt_rate_deg_s=2.0)
    with pytest.raises(CameraError, match="dt_s must not be negative"):
        step(HeadState(T0, 0, 0, 30), None, -1.0, LIMITS)


# A start state whose braking point lies inside the tilt range (else overshoot is forced).
states = st.builds(
    HeadState,
    t_s=st.just(T0),
    pan_deg=st.floats(-180.0, 180.0),
    tilt_deg=st.floats(-80.0, 20.0),
    hfov_deg=st.floats(3.0, 60.0),
    pan_rate_deg_s=st.floats(-60.0, 60.0),
    tilt_rate_deg_s=st.floats(-40.0, 40.0),
)
targets = st.tuples(st.floats(-180.0, 180.0), st.floats(-90.0, 30.0), st.floats(3.0, 60.0))


@settings(max_examples=150, deadline=None)
@given(start=states, target=targets, dt=st.sampled_from([0.01, 0.05, 0.1]))
def test_moves_respect_limits_and_arrive_when_promised(start, target, dt):
    pan, tilt, hfov = target
    command = HeadCommand(pan_deg=pan, tilt_deg=tilt, hfov_deg=hfov)
    t_reach = time_to_reach(start, pan, tilt, hfov, LIMITS)
    seq = run(start, command, dt, int(math.ceil(t_reach / dt)) + 10)
    tol = 1e-9
    for a, b in zip(seq, seq[1:], strict=False):
        assert abs(b.pan_rate_deg_s) <= 60.0 + tol
        assert abs(b.tilt_rate_deg_s) <= 40.0 + tol
        # finite differences: acceleration, and the distance the rate allows
        assert abs(b.pan_rate_deg_s - a.pan_rate_deg_s) <= 120.0 * dt + tol
        assert abs(b.tilt_rate_deg_s - a.tilt_rate_deg_s) <= 120.0 * dt + tol
        assert abs(wrap(b.pan_deg - a.pan_deg)) <= 60.0 * dt + tol
        assert abs(b.tilt_deg - a.tilt_deg) <= 40.0 * dt + tol
        assert abs(b.hfov_deg - a.hfov_deg) <= 10.0 * dt + tol
        assert -90.0 - tol <= b.tilt_deg <= 30.0 + tol
    arrived = step(start, command, t_reach, LIMITS)
    assert abs(wrap(arrived.pan_deg - pan)) <= 1e-9
    assert arrived.tilt_deg == pytest.approx(tilt, abs=1e-9)
    assert arrived.hfov_deg == pytest.approx(hfov, abs=1e-9)
    assert (arrived.pan_rate_deg_s, arrived.tilt_rate_deg_s) == (0.0, 0.0)
    for s in seq[-5:]:  # and it stays
        assert (s.pan_deg, s.tilt_deg, s.hfov_deg) == (arrived.pan_deg, tilt, hfov)
    if t_reach > 0.05:  # time-optimal: not there any sooner
        early = step(start, command, t_reach - 0.02, LIMITS)
        off = (
            abs(wrap(early.pan_deg - pan)),
            abs(early.tilt_deg - tilt),
            abs(early.hfov_deg - hfov),
            abs(early.pan_rate_deg_s),
            abs(early.tilt_rate_deg_s),
        )
        assert max(off) > 1e-6


@settings(max_examples=150, deadline=None)
@given(
    start=states,
    target=targets,
    rates=st.tuples(st.floats(-90, 90), st.floats(-60, 60), st.floats(-20, 20)),
    absolute=st.booleans(),
)
def test_ten_small_steps_equal_one_large_step(start, target, rates, absolute):
    # step integrates piecewise-constant acceleration exactly and the rest of a
    # time-optimal profile is the same profile seen from any point on it, so
    # subdividing only changes float rounding (and the 1e-9 snap onto the target).
    if absolute:
        command = HeadCommand(pan_deg=target[0], tilt_deg=target[1], hfov_deg=target[2])
    else:
        command = HeadCommand(
            pan_rate_deg_s=rates[0], tilt_rate_deg_s=rates[1], zoom_rate_deg_s=rates[2]
        )
    fine = run(start, command, 0.1, 10)[-1]
    coarse = step(start, command, 1.0, LIMITS)
    assert fine.t_s == pytest.approx(coarse.t_s, abs=1e-6)
    assert abs(wrap(fine.pan_deg - coarse.pan_deg)) <= 1e-6
    assert fine.tilt_deg == pytest.approx(coarse.tilt_deg, abs=1e-6)
    assert fine.hfov_deg == pytest.approx(coarse.hfov_deg, abs=1e-6)
    assert fine.pan_rate_deg_s == pytest.approx(coarse.pan_rate_deg_s, abs=1e-6)
    assert fine.tilt_rate_deg_s == pytest.approx(coarse.tilt_rate_deg_s, abs=1e-6)
