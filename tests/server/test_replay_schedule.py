"""The replay's schedule: loops in step, and no two scenarios' vehicles on top of each other."""

from __future__ import annotations

import numpy as np
import pytest
from server_helpers import scenario_stream

from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import ScenarioParams, make_scenario
from demtrack.server.replay import LOOP_GAP_S
from demtrack.server.replay_schedule import commensurate_periods, replay_schedule

pytestmark = pytest.mark.timeout(300)

NAMES = ("vehicle-run", "pedestrians", "passing-vehicles")


def test_periods_divide_one_hyper_period_and_stretch_little():
    spans = [148.5, 85.4, 36.5]
    periods, hyper = commensurate_periods(spans, 5.0)
    for span, period in zip(spans, periods, strict=True):
        need = span + 5.0
        assert need <= period <= 1.1 * need + 1e-9
        assert hyper / period == pytest.approx(round(hyper / period), abs=1e-9)
    assert commensurate_periods([10.0], 5.0) == ([15.0], 15.0)


def _longest_overlap_s(scenarios, periods, offsets, hyper, gap_m=1.5, dt=0.02):
    """Brute force: the longest time (s) two vehicles of different scenarios stay within
    ``gap_m`` of each other, over a hyper-period sampled every ``dt``."""
    t = np.arange(0.0, hyper, dt)
    tracks = []
    for j, (sc, period) in enumerate(zip(scenarios, periods, strict=True)):
        for o in offsets[j]:
            for truth in sc.truths:
                if truth.cls == "vehicle":
                    tracks.append((j, truth.at(np.mod(t - o, period))[:, :2]))
    longest = 0
    for a in range(len(tracks)):
        for b in range(a + 1, len(tracks)):
            if tracks[a][0] == tracks[b][0]:
                continue
            close = np.linalg.norm(tracks[a][1] - tracks[b][1], axis=1) < gap_m
            run = 0
            for c in close.tolist():
                run = run + 1 if c else 0
                longest = max(longest, run)
    return longest * dt


@pytest.mark.parametrize("copies", [1, 2, 4])
def test_vehicles_of_different_scenarios_only_meet_in_passing(sample_site_dir, copies):
    site = load_site(sample_site_dir)
    scenarios = [make_scenario(site, n, ScenarioParams(seed=0)) for n in NAMES]
    spans = [max(d.t_s for d in sc.detections) for sc in scenarios]
    periods, offsets = replay_schedule(spans, [sc.truths for sc in scenarios], copies, 10.0, 5.0)
    _, hyper = commensurate_periods(spans, 5.0)
    for j in range(len(NAMES)):  # copies k / copies of the period apart, whole frames
        for k, o in enumerate(offsets[j]):
            assert abs(o - offsets[j][0] - k * periods[j] / copies) <= 0.1 + 1e-9
            assert o * 10 == pytest.approx(round(o * 10), abs=1e-6)
    # at most an overtaking moment within 1.5 m (more copies on one road must overtake)
    assert _longest_overlap_s(scenarios, periods, offsets, hyper) <= 1.5
    # started together (the old replay), two cars drive on top of each other for 30 s
    naive = [[k * p / copies for k in range(copies)] for p in periods]
    assert _longest_overlap_s(scenarios, periods, naive, hyper) >= 10.0


def test_stream_follows_the_schedule(sample_site_dir):
    site = load_site(sample_site_dir)
    scenarios = [make_scenario(site, n, ScenarioParams(seed=0)) for n in NAMES]
    spans = [max(d.t_s for d in sc.detections) for sc in scenarios]
    periods, offsets = replay_schedule(spans, [sc.truths for sc in scenarios], 1, 10.0, LOOP_GAP_S)
    t0 = 50.0
    frames = list(scenario_stream(site, list(NAMES), t0, loop=False))
    boxes = {(f.t_s, f.sensor, tuple(r["bbox"])) for f in frames for r in f.records}
    for j, sc in enumerate(scenarios):
        for d in sc.detections:
            assert (round(d.t_s + t0 + offsets[j][0], 6), d.sensor, tuple(d.bbox)) in boxes
    # looping: the second loop of each scenario starts one period after the first
    looped = scenario_stream(site, list(NAMES), t0)
    times = set()
    for f in looped:
        if f.t_s > t0 + 2.2 * max(periods):
            break
        times.add(f.t_s)
    for j, sc in enumerate(scenarios):
        first = min(d.t_s for d in sc.detections)
        assert round(first + t0 + offsets[j][0] + periods[j], 6) in times
