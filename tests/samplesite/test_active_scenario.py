"""The active-handoff scenario: heads that follow the car, their telemetry, the renderer."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from demtrack.core.camera.head_motion import HeadState, SlewLimits
from demtrack.core.camera.pose_series import PoseSample, camera_at
from demtrack.core.errors import SiteError
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.site.folder import load_site
from demtrack.samplesite.active_scenario import ActiveParams, HeadTrack, _limits, telemetry
from demtrack.samplesite.scenarios import ACTIVE_SCENARIOS, SCENARIOS, make_scenario
from demtrack.samplesite.scene_render import (
    STAT_KEYS,
    ScenarioParams,
    frame_times,
    render_frame,
    render_targets,
    site_world,
    true_yaws,
)


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


@pytest.fixture(scope="module")
def active(site):
    return make_scenario(site, "active-handoff")


@pytest.fixture(scope="module")
def fixed(site):
    return make_scenario(site, "active-handoff", fixed_cameras=True)


def test_registered_beside_the_others():
    assert "active-handoff" in SCENARIOS and ACTIVE_SCENARIOS <= set(SCENARIOS)


def test_sample_site_sensors_are_resting_ptz_heads(site):
    for s in site.sensors.values():
        assert not s.active and s.slew_limits is not None
        lim = _limits(s)
        lens = np.degrees(2 * np.arctan2(s.head.intrinsics.width / 2, s.head.intrinsics.fx))
        assert lim.hfov_max_deg == pytest.approx(lens, abs=1e-6)  # the lens is the widest
        assert lim.hfov_min_deg < 10.0


def test_limits_without_slew_limits_never_exceed_the_lens(site):
    s = replace(next(iter(site.sensors.values())), slew_limits=None)
    lim = _limits(s)
    lens = np.degrees(2 * np.arctan2(s.head.intrinsics.width / 2, s.head.intrinsics.fx))
    assert lim.hfov_max_deg == pytest.approx(min(lens, 179.0))
    assert lim.pan_rate_deg_s == SlewLimits().pan_rate_deg_s


def test_fixed_scenarios_carry_no_poses(site):
    sc = make_scenario(site, "passing-vehicles")
    assert sc.poses == {} and set(sc.stats) == set(STAT_KEYS)


def test_per_frame_renderer_equals_the_vectorised_one(site):
    """render_frame, frame by frame with the fixed cameras, is render_targets' twin."""
    world = site_world(site)
    targets = SCENARIOS["passing-vehicles"](world)
    params = ScenarioParams(seed=3)
    whole = render_targets(site, world, "passing-vehicles", targets, params)
    yaws = true_yaws(site)
    cams = {
        sid: camera_at(s.head.with_mount_yaw(yaws[sid]), PoseSample(0.0, s.pan_deg, s.tilt_deg))
        for sid, s in site.sensors.items()
    }
    caster = RayCaster.from_dem(site.dem)
    rng = np.random.default_rng(params.seed)
    stats = dict.fromkeys(STAT_KEYS, 0)
    dets = []
    for t in frame_times(targets, params.rate_hz):
        got, _ = render_frame(float(t), cams, targets, world, caster, params, rng, stats)
        dets += got
    assert dets == whole.detections
    stats["frames"] = whole.stats["frames"]
    assert stats == whole.stats


def test_telemetry_is_late_by_the_latency_and_not_on_the_frame_clock():
    t = np.arange(0.0, 10.0001, 0.025)
    track = HeadTrack(t, 170.0 + 20.0 * t, -5.0 - 0.5 * t, 40.0 - t)  # pan crosses 180
    rng = np.random.default_rng(0)
    series = telemetry(track, 15.0, 1.0, 9.0, 0.0, 0.08, rng)
    stamps = series.t_s
    assert np.allclose(np.diff(stamps), 1 / 15.0)
    assert not np.allclose((stamps * 10) % 1, 0.0)  # not aligned with 10 Hz frames
    frames = np.arange(2.0, 8.0, 0.1)
    at = series.at(frames, latency_s=0.08)
    assert at.ok.all()
    pan, tilt, hfov = track.at(frames)  # the truth at the frame times
    assert np.allclose(((at.pan_deg - pan + 180) % 360) - 180, 0.0, atol=1e-9)
    assert np.allclose(at.tilt_deg, tilt, atol=1e-9) and np.allclose(at.hfov_deg, hfov)
    # Read without the latency, a head turning at 20 deg/s is 1.6 degrees behind.
    late = series.at(frames, latency_s=0.0)
    assert np.allclose(((pan - late.pan_deg + 180) % 360) - 180, 1.6, atol=1e-6)


def test_telemetry_noise_is_the_stated_one():
    t = np.arange(0.0, 200.0, 0.1)
    track = HeadTrack(t, np.zeros_like(t), np.full_like(t, -10.0), np.full_like(t, 30.0))
    s = telemetry(track, 20.0, 0.0, 200.0, 0.05, 0.08, np.random.default_rng(1))
    tilts = np.array([p.tilt_deg for p in s.samples()])
    assert np.std(tilts + 10.0) == pytest.approx(0.05, rel=0.05)


def test_head_track_unwraps_pan():
    states = [HeadState(0.1 * i, 175.0 + 2.0 * i, 0.0, 30.0) for i in range(6)]
    tr = HeadTrack.from_states(states)
    assert np.all(np.diff(tr.pan_deg) > 0)
    pan, _, _ = tr.at(np.array([0.35]))  # between 181 and 183: wrapped to -178
    assert pan[0] == pytest.approx(-178.0)


def test_bad_active_parameters_are_refused():
    with pytest.raises(SiteError, match="active scenario parameters"):
        ActiveParams(telemetry_hz=(0.0,))
    with pytest.raises(SiteError):
        ActiveParams(substeps=0)


def test_heads_move_zoom_and_hand_over(active, site):
    assert set(active.poses) == set(site.sensors)
    t0, t1 = active.truths[0].t_s[0], active.truths[0].t_s[-1]
    for series in active.poses.values():
        assert series.t_s[0] < t0 and series.t_s[-1] > t1  # the whole run is covered
        assert series.has_zoom
    pans = {sid: np.ptp([p.pan_deg for p in s.samples()]) for sid, s in active.poses.items()}
    hfovs = {sid: min(p.hfov_deg for p in s.samples()) for sid, s in active.poses.items()}
    assert max(pans.values()) > 60.0  # a head turned with the car
    lens = {
        sid: np.degrees(2 * np.arctan2(s.head.intrinsics.width / 2, s.head.intrinsics.fx))
        for sid, s in site.sensors.items()
    }
    assert any(hfovs[sid] < 0.6 * lens[sid] for sid in hfovs)  # and zoomed in on it
    assert active.stats["handoffs"] >= 3
    assert {d.sensor for d in active.detections} == set(site.sensors)


def test_heads_keep_the_car_in_view_longer_than_fixed_cameras(active, fixed):
    assert active.stats["target_frames"] == fixed.stats["target_frames"]
    assert active.in_view_share > fixed.in_view_share + 0.03
    assert active.in_view_share > 0.9
    assert [t.p_enu.tolist() for t in active.truths] == [t.p_enu.tolist() for t in fixed.truths]


def _box_misses(site, sc, latency_s):
    """Distance (px) from each true car's projection, at the reported pose, to its box."""
    truth = sc.truths[0]
    yaws = true_yaws(site)
    out = []
    for d in sc.detections[::7]:
        s = site.sensors[d.sensor]
        pose = sc.poses[d.sensor].at([d.t_s], latency_s=latency_s).sample(0)
        cam = camera_at(s.head.with_mount_yaw(yaws[d.sensor]), pose, s.zoom)
        p = truth.at(d.t_s)[0] + [0.0, 0.0, 0.75]
        u, v, front = cam.project(p)
        if not front[0]:
            continue
        uc, vc = 0.5 * (d.bbox[0] + d.bbox[2]), 0.5 * (d.bbox[1] + d.bbox[3])
        out.append(float(np.hypot(u[0] - uc, v[0] - vc)))
    return np.array(out)


def test_detections_agree_with_the_telemetry_read_at_its_latency(site, active):
    """Rendering, telemetry and latency sign tie together: the true car, projected with
    the reported pose read ``latency_s`` later, lands on its boxes; read early it does not
    (the heads turn), and false alarms stay a small minority."""
    right = _box_misses(site, active, 0.08)
    wrong = _box_misses(site, active, -0.08)
    assert np.median(right) < 5.0
    assert np.mean(right < 25.0) > 0.9
    assert np.median(wrong) > 2.0 * np.median(right)


def test_heads_turn_within_their_own_slew_limits(active, site):
    """The reported pan rates (5-sample means, so the 0.05 deg noise averages out) never
    pass each head's limit (the mast head's 45 deg/s is not the others' 60); a slew
    reaches it."""
    peaks = []
    for sid, series in active.poses.items():
        samples = series.samples()
        t = np.array([p.t_s for p in samples])
        pan = np.degrees(np.unwrap(np.radians([p.pan_deg for p in samples])))
        rate = np.convolve(np.diff(pan) / np.diff(t), np.ones(5) / 5, "valid")
        limit = _limits(site.sensors[sid]).pan_rate_deg_s
        assert np.abs(rate).max() <= limit + 2.0
        peaks.append(np.abs(rate).max() / limit)
    assert max(peaks) > 0.9
    fastest = {sid: _limits(site.sensors[sid]).pan_rate_deg_s for sid in site.sensors}
    assert len(set(fastest.values())) == 2
