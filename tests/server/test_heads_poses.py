"""The controller's poses geolocate the detections of their moment (through the pose ingest).

A simulated head on a test clock, polled by the controller, fed to the real pose ingest
(:class:`~demtrack.server.ingest.poses.PoseIngest` on a real pipeline and store): detections
before a slew are geolocated with the resting pose, those after it with the slewed one.
The oracle is the fixed camera of a site whose sensor stands at that pose
(``dataclasses.replace`` of its pan and tilt), built independently of the pose path.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
from heads_helpers import T0, Clock, active_site
from server_helpers import walk

from demtrack.core.camera.head_motion import HeadState, time_to_reach
from demtrack.core.site.folder import load_site
from demtrack.server.heads.config import active_head_configs, build_adapter
from demtrack.server.heads.controller import HeadController, HeadUnit
from demtrack.server.heads.service import pose_feed
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.ingest.poses import PoseIngest
from demtrack.server.store.database import Store

pytestmark = pytest.mark.timeout(600)


def rays(store, t_from, t_to):
    bodies = [b for b in store.fixes(0, 100_000) if b["hits"] and t_from <= b["t_s"] <= t_to]
    return np.array([b["origin_enu"] + b["direction_enu"] for b in bodies])


def oracle_rays(site, pan, tilt, dets, path):
    moved = dataclasses.replace(site.sensors["cam1"], pan_deg=pan, tilt_deg=tilt, active=False)
    p = Pipeline(dataclasses.replace(site, sensors={**site.sensors, "cam1": moved}),
                 Store(path), "kalman", lambda _m: None)  # fmt: skip
    p.start()
    p.ingest(dets)
    return rays(p.store, -np.inf, np.inf)


def test_detections_are_geolocated_at_the_heads_pose_of_their_moment(sample_site_dir, tmp_path):
    site = load_site(active_site(sample_site_dir, tmp_path / "site", {"cam1": {"active": True}}))
    clock = Clock()
    pipeline = Pipeline(site, Store(tmp_path / "c.sqlite3"), "kalman", lambda _m: None,
                        pose_interval_s=0.0)  # fmt: skip
    pipeline.start()
    feed = pose_feed(SimpleNamespace(poses=PoseIngest(pipeline), site=site))
    (config,) = active_head_configs(site)
    unit = HeadUnit("cam1", build_adapter(site, config, clock), config.limits)
    ctl = HeadController(site, [unit], pipeline, feed, period_s=0.1, clock=clock)
    rest_pan, rest_tilt = site.sensor("cam1").pan_deg, site.sensor("cam1").tilt_deg

    def run(seconds):
        for _ in range(int(round(seconds * 10))):
            clock.t += 0.1
            ctl.tick()

    run(2.0)
    pan, tilt = rest_pan + 12.0, rest_tilt - 3.0
    ctl.slew("cam1", pan, tilt, None)
    t_slew = clock.t
    reach = time_to_reach(
        HeadState(t_slew, rest_pan, rest_tilt, 60.0), pan, tilt, None, config.limits
    )
    run(reach + 2.5)
    ctl.flush_poses()
    before = walk(n=10, t0=T0 + 0.5, dt=0.1)  # at rest
    after = walk(n=10, t0=t_slew + reach + 0.5, dt=0.1)  # arrived
    pipeline.ingest(before + after)
    got_before = rays(pipeline.store, T0, t_slew)
    got_after = rays(pipeline.store, t_slew + reach + 0.1, np.inf)
    want_before = oracle_rays(site, rest_pan, rest_tilt, before, tmp_path / "a.sqlite3")
    want_after = oracle_rays(site, pan, tilt, after, tmp_path / "b.sqlite3")
    assert len(got_before) == len(want_before) == 10
    assert len(got_after) == len(want_after) == 10
    np.testing.assert_allclose(got_before, want_before, rtol=0, atol=1e-9)
    np.testing.assert_allclose(got_after, want_after, rtol=0, atol=1e-9)
    # and the slew mattered: the two poses' rays differ
    assert np.abs(got_after[:, 3:] - got_before[:, 3:]).max() > 0.05
