"""Replay options for a busier scene: staggered copies, the cameras' rate, a duration."""

from __future__ import annotations

import itertools

import pytest
from server_helpers import make_app, scenario_stream

from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import ScenarioParams, make_scenario
from demtrack.server.replay import LOOP_GAP_S, scenario_frames

pytestmark = pytest.mark.timeout(300)

NAME = "passing-vehicles"


def test_copies_are_the_seeded_scenarios_staggered_over_the_period(sample_site_dir):
    site = load_site(sample_site_dir)
    rate = 5.0
    copies = [
        scenario_frames(make_scenario(site, NAME, ScenarioParams(seed=k, rate_hz=rate)).detections)
        for k in range(3)
    ]
    period = copies[0][-1].t_s + LOOP_GAP_S
    t0 = 100.0
    got = list(scenario_stream(site, [NAME], t0, loop=False, copies=3, rate_hz=rate))
    # Every record of every copy, each at its copy's time plus a whole-frame offset of
    # k/3 of the period: the same multiset of (time, sensor, box) in the merged stream.
    want = []
    for k, frames in enumerate(copies):
        offset = round(k * period / 3 * rate) / rate
        assert abs(offset - k * period / 3) <= 0.5 / rate
        want += [
            (round(f.t_s + t0 + offset, 6), f.sensor, tuple(r["bbox"]))
            for f in frames
            for r in f.records
        ]
    have = [(f.t_s, f.sensor, tuple(r["bbox"])) for f in got for r in f.records]
    assert sorted(have) == sorted(want)
    assert all(r["t"] == f.t_s for f in got for r in f.records)
    # Copies differ (their own noise seed), frames stay on the 5 Hz grid and in order.
    assert copies[0][0].records[0]["bbox"] != copies[1][0].records[0]["bbox"]
    assert all(abs(f.t_s * rate - round(f.t_s * rate)) < 1e-6 for f in got)
    keys = [(f.t_s, f.sensor) for f in got]
    assert keys == sorted(keys) and len(set(keys)) == len(keys)  # one batch per camera frame


def test_duration_ends_a_looping_replay(sample_site_dir):
    site = load_site(sample_site_dir)
    frames = list(scenario_stream(site, [NAME], 10.0, copies=2, duration_s=90.0))
    assert frames and frames[-1].t_s < 100.0
    # Looping and the second copy fill the window: frames close to its end exist.
    assert frames[-1].t_s > 99.0
    looped = scenario_stream(site, [NAME], 10.0, copies=2)
    head = list(itertools.takewhile(lambda f: f.t_s < 100.0, looped))
    assert [(f.t_s, f.sensor) for f in head] == [(f.t_s, f.sensor) for f in frames]


def test_copies_must_be_positive(sample_site_dir):
    with pytest.raises(ValueError, match="at least 1"):
        scenario_stream(load_site(sample_site_dir), [NAME], 0.0, copies=0)


def test_settings_carry_the_replay_options(sample_site_dir, tmp_path, monkeypatch):
    monkeypatch.setenv("DEMTRACK_REPLAY_COPIES", "4")
    monkeypatch.setenv("DEMTRACK_REPLAY_RATE_HZ", "2.5")
    monkeypatch.setenv("DEMTRACK_REPLAY_DURATION_S", "60")
    monkeypatch.setenv("DEMTRACK_REPLAY_BATCH_S", "0.25")
    s = make_app(sample_site_dir, tmp_path).state.settings
    assert (s.replay_copies, s.replay_rate_hz, s.replay_duration_s) == (4, 2.5, 60.0)
    assert s.replay_batch_s == 0.25
    monkeypatch.setenv("DEMTRACK_REPLAY_BATCH_S", "-1")
    with pytest.raises(ValueError, match="replay_batch_s"):
        make_app(sample_site_dir, tmp_path)
    monkeypatch.delenv("DEMTRACK_REPLAY_BATCH_S")
    monkeypatch.setenv("DEMTRACK_REPLAY_COPIES", "0")
    with pytest.raises(ValueError, match="replay_copies"):
        make_app(sample_site_dir, tmp_path)
