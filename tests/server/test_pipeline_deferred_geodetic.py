"""Fix bodies whose geodetic fields are filled by the track points' conversion.

The pipeline converts a batch's fix hits in the same pyproj call as its track points;
the bodies must be exactly those of a conversion of their own points alone.
"""

from __future__ import annotations

import json

import numpy as np
from server_helpers import vehicle_run_pipeline

from demtrack.core.geolocation.fix_builder import build_fixes


def test_deferred_geodetic_fields_equal_those_of_their_own_call(sample_site_dir, tmp_path):
    site, p, records = vehicle_run_pipeline(sample_site_dir, tmp_path, until_s=8.0)
    for r in records[: len(records) // 2]:  # some tracks, so points are converted too
        p.ingest([r])
    validated, _ = p._validate(records[len(records) // 2 :])
    pending = list(enumerate(validated, start=10_000))
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(12):  # random small groups of the pending detections
        k = int(rng.integers(1, 5))
        start = int(rng.integers(0, len(pending) - k))
        group = pending[start : start + k]
        fixes, _ = build_fixes(site, [d for _, d in group])
        deferred, unfilled = p._fix_bodies(group, fixes)
        # the oracle: the bodies with the fields of a geodetic call of their own
        # (hits and road points: one or two (points, dicts) pairs, converted together)
        pts = np.concatenate([a for a, _ in unfilled])
        dicts = [d for _, ds in unfilled for d in ds]
        lat, lon, h = (np.atleast_1d(a).tolist() for a in site.frame.to_geodetic(*pts.T))
        for d, values in zip(dicts, zip(lat, lon, h, strict=True), strict=True):
            assert (d["lat_deg"], d["lon_deg"], d["h_m"]) == (None, None, None)
            d["lat_deg"], d["lon_deg"], d["h_m"] = values
        whole = json.dumps(deferred)
        for d in dicts:
            d["lat_deg"] = d["lon_deg"] = d["h_m"] = None
        before = dict(p._points)
        p._refresh_points(p.tracker.tracks(include_ended=False), unfilled)
        assert json.dumps(deferred) == whole
        # the tracks' cached points are the same as a call without the extra points
        p2 = {i: v[1] for i, v in p._points.items()}
        p._points = before
        p._refresh_points(p.tracker.tracks(include_ended=False))
        assert json.dumps(p2, sort_keys=True) == json.dumps(
            {i: v[1] for i, v in p._points.items()}, sort_keys=True
        )
        checked += sum(b is not None for b in deferred)
    assert checked > 10
