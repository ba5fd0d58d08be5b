"""The live server's tracks against the offline tracker's, on the same detections.

``vehicle-run`` has one vehicle. Its detections go through the server's ingest pipeline
(a real SQLite store, fixes made back from their stored bodies, the reorder buffer, the
online tracker fed batch by batch) in the console replay's 1x batching (0.1 s of frames per
call) and 10x batching (1 s per call), and must give the tracks offline ``kalman`` gives:
one track, no stub, no ``track_ended`` announced for a track that later goes on.
"""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.commands.evaluate import n_stubs, tracking_config
from demtrack.core.errors import TrackingError
from demtrack.core.geolocation.fix_builder import build_fixes
from demtrack.core.site.folder import load_site
from demtrack.core.tracking import evaluate, run_tracker
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.ingest.offline_replay import early_ended, replay_detections


@pytest.fixture(scope="module")
def vehicle_run(sample_site_dir):
    site = load_site(sample_site_dir)
    sc = make_scenario(site, "vehicle-run")
    fixes, _ = build_fixes(site, sc.detections)
    offline = run_tracker(fixes, "kalman", roads=site.roads, config=tracking_config())
    return site, sc, offline


@pytest.fixture(scope="module", params=[0.1, 1.0], ids=["1x", "10x"])
def live(request, vehicle_run):
    site, sc, _ = vehicle_run
    return replay_detections(site, sc.detections, method="kalman", batch_s=request.param)


def test_server_tracks_are_the_offline_tracks(vehicle_run, live):
    _, sc, offline = vehicle_run
    assert len(offline) == len(sc.truths) == 1  # one vehicle, one track
    assert [t.id for t in live.tracks] == [t.id for t in offline]
    assert n_stubs(live.tracks) == n_stubs(offline) == 0
    m = evaluate(list(live.tracks), sc.truths)
    assert (m.n_tracks, m.n_false_tracks, m.fragmentation, m.id_switches) == (1, 0, 0, 0)
    # the same points: the live track lacks only the fixes still waiting in the reorder
    # buffer (0.5 s) and the tracker's open step; its newest points may yet be revised
    a, b = live.tracks[0], offline[0]
    n = len(a.points)
    assert len(b.points) - 12 <= n <= len(b.points)
    np.testing.assert_array_equal(a.t_s, b.t_s[:n])
    lag = tracking_config().smoothing_lag + 1
    np.testing.assert_allclose(a.p_enu[: n - lag], b.p_enu[: n - lag], atol=1e-9)


def test_no_track_is_announced_ended_and_then_goes_on(live):
    # the north-bend occlusion: longer than the 4 s coast limit, inside the 30 s window
    track = live.tracks[0]
    assert any(t1 - t0 > 4.0 for t0, t1 in track.gaps)
    assert early_ended(live) == []
    assert live.ended == ()  # the one vehicle never left for good
    assert [i for i, _ in live.confirmed] == [1]


def test_replay_batch_must_be_positive(vehicle_run):
    site = vehicle_run[0]
    with pytest.raises(TrackingError, match="replay batch must be a positive number"):
        replay_detections(site, [], batch_s=0.0)
    assert replay_detections(site, [], batch_s=1.0).tracks == ()
