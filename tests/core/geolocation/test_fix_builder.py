"""Fix building from detections, and the sample-site scenarios' truth (round trips)."""

from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.geolocation.fix_builder import (
    build_fixes,
    default_foot_offsets,
    footprint_variances,
)
from demtrack.core.site.folder import load_site
from demtrack.core.tracking import Detection
from demtrack.samplesite.scenarios import (
    ScenarioParams,
    make_scenario,
    site_world,
    true_cameras,
)


@pytest.fixture(scope="module")
def site(sample_site_dir):
    return load_site(sample_site_dir)


def test_a_box_gives_the_geolocation_of_its_bottom_centre(site):
    cam = site.sensor("cam1").camera
    box = (600.0, 500.0, 660.0, 540.5)
    det = Detection(1.0, "cam1", box, "vehicle")
    (fix,), report = build_fixes(site, [det], foot_offset_m={"vehicle": 0.0, "human": 0.0})
    (g,) = site.geolocator().geolocate(cam, [630.0], [540.5], rule="all")
    assert report.n_fixes == 1 and fix.n_hits == len(g.hits) >= 1
    np.testing.assert_allclose(fix.hits_enu, [h.p_enu for h in g.hits], atol=1e-9)
    # covariance: the geolocator's plus the footprint's extent (isotropic across the ray,
    # the heading spread of the foot-to-centre distance along it)
    along, across = footprint_variances()["vehicle"]
    assert across == pytest.approx((4.5**2 + 1.8**2) / 24)
    d2 = g.direction_enu[:2] / np.linalg.norm(g.direction_enu[:2])
    extent = across * np.eye(2) + (along - across) * np.outer(d2, d2)
    want = np.array([h.cov_en_m2 for h in g.hits]) + extent
    np.testing.assert_allclose(fix.hit_cov_en_m2, want, atol=1e-12)
    np.testing.assert_allclose(fix.hit_sigma_m, np.sqrt(np.linalg.eigvalsh(want)[:, -1]))
    assert np.all(fix.hit_sigma_m >= [h.sigma_m for h in g.hits])
    np.testing.assert_allclose(fix.origin_enu, g.origin_enu)
    # With the default foot offset every hit moves (L + W) / pi along the ray's ground track.
    (moved,), _ = build_fixes(site, [det])
    d = g.direction_enu[:2] / np.linalg.norm(g.direction_enu[:2])
    shift = moved.hits_enu[:, :2] - fix.hits_enu[:, :2]
    np.testing.assert_allclose(shift, np.outer(np.ones(fix.n_hits), d) * (6.3 / np.pi), atol=1e-9)
    assert default_foot_offsets()["vehicle"] == pytest.approx(6.3 / np.pi)


def test_bad_detections_are_counted_and_skipped(site):
    dets = [
        Detection(1.0, "cam1", (600, 500, 660, 540), "vehicle"),
        Detection(1.1, "cam9", (600, 500, 660, 540), "vehicle"),  # unknown sensor
        Detection(1.2, "cam1", (600, 500, 660, 900), "vehicle"),  # below the image
        Detection(0.5, "cam1", (600, 500, 660, 540), "vehicle"),  # backwards for cam1
        Detection(0.5, "cam2", (600, 500, 660, 540), "human"),  # fine: another sensor
    ]
    fixes, report = build_fixes(site, dets)
    assert [f.detection_index for f in fixes] == [0, 4]
    assert report.counts["unknown_sensor"] == 1
    assert report.counts["outside_image"] == 1
    assert report.counts["time_backwards"] == 1
    assert "skipped 3" in report.summary()


def test_truth_projects_and_geolocates_back_on_open_ground(site):
    world = site_world(site)
    cam = site.sensor("cam1").camera
    # Open-field points seen by cam1, on the site DEM: project, then geolocate the pixel.
    xy = np.array([[-60.0, -20.0], [-20.0, -30.0], [-80.0, 0.0]])
    p = np.column_stack([xy, site.dem.sample(xy[:, 0], xy[:, 1])])
    u, v, front = cam.project(p)
    assert front.all() and cam.in_image(u, v).all()
    for k, g in enumerate(site.geolocator().geolocate(cam, u, v, rule="last")):
        assert np.linalg.norm(g.best.p_enu - p[k]) < 0.01
    # Against the analytic ground and the true camera, the error is the calibration's and
    # the DEM's: centimetres to decimetres at these grazing angles.
    true_cam = true_cameras(site)["cam1"]
    q = np.column_stack([xy, world.ground_z(xy[:, 0], xy[:, 1])])
    u, v, _ = true_cam.project(q)
    for k, g in enumerate(site.geolocator().geolocate(cam, u, v, rule="last")):
        assert np.linalg.norm(g.best.p_enu[:2] - q[k, :2]) < 0.3


def test_scenarios_are_deterministic_and_seeded(site):
    params = ScenarioParams(seed=3)
    a = make_scenario(site, "pedestrians", params)
    b = make_scenario(site, "pedestrians", params)
    c = make_scenario(site, "pedestrians", ScenarioParams(seed=4))
    assert [(d.t_s, d.sensor, d.bbox) for d in a.detections] == [
        (d.t_s, d.sensor, d.bbox) for d in b.detections
    ]
    assert [d.bbox for d in a.detections] != [d.bbox for d in c.detections]
    assert len(a.truths) == 3 and a.stats["detected"] > 1000


def test_noise_free_boxes_sit_on_the_true_targets(site):
    sc = make_scenario(
        site, "pedestrians", ScenarioParams(noise_px=0, p_miss=0, false_alarm_rate=0)
    )
    fixes, _ = build_fixes(site, sc.detections)
    err = []
    for f in fixes:
        truth = min(
            (tr.at(f.t_s)[0] for tr in sc.truths if np.isfinite(tr.at(f.t_s)[0, 0])),
            key=lambda p: np.min(np.linalg.norm(f.hits_enu[:, :2] - p[:2], axis=1)),
        )
        err.append(np.min(np.linalg.norm(f.hits_enu[:, :2] - truth[:2], axis=1)))
    # A person's foot point, 0.3 m offset applied: well under a metre nearly always.
    assert np.median(err) < 0.3 and np.percentile(err, 90) < 1.0
