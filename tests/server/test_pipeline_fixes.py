"""The tracker's fix in the live path is exactly the one the start-up replay rebuilds."""

from __future__ import annotations

import json

import numpy as np
import pytest

from demtrack.core.site import load_site
from demtrack.samplesite.scenarios import make_scenario
from demtrack.server.db import Store
from demtrack.server.pipeline import Pipeline, fix_from_body

pytestmark = pytest.mark.timeout(600)


def test_live_fixes_equal_the_stored_bodies_fixes(sample_site_dir, tmp_path):
    site = load_site(sample_site_dir)
    dets = [d for d in make_scenario(site, "vehicle-run").detections if d.t_s < 6.0]
    records = [
        {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls, "score": 0.5}
        for d in dets
    ]
    p = Pipeline(site, Store(tmp_path / "f.sqlite3"), "kalman", lambda _m: None)
    p.start()
    validated, _ = p._validate(records)
    pending = list(enumerate(validated, start=1))
    from demtrack.core.fix_builder import build_fixes

    fixes, _ = build_fixes(site, validated)
    bodies = p._fix_bodies(pending, fixes)
    live = p._queued_fixes
    n = 0
    for body in bodies:
        if body is None:
            continue
        a = live[body["detection_id"]]
        b = fix_from_body(json.loads(json.dumps(body)))  # as the replay reads it back
        for name in ("t_s", "sensor", "cls", "detection_index", "score", "hit_cov_en_m2"):
            assert getattr(a, name) == getattr(b, name)
        for name in ("origin_enu", "direction_enu", "hits_enu", "hit_sigma_m", "road_hit_enu"):
            x, y = getattr(a, name), getattr(b, name)
            assert (x is None) == (y is None)
            if x is not None:
                assert x.dtype == y.dtype and x.shape == y.shape
                assert x.tobytes() == y.tobytes()  # bit for bit
                assert not x.flags.writeable
        n += 1
    assert n > 50
    # a malformed body still goes through the checked constructor
    bad = dict(bodies[0] or next(b for b in bodies if b), origin_enu=[0.0, float("nan"), 0.0])
    with pytest.raises(ValueError):
        fix_from_body(bad)
    assert np.isfinite(fix_from_body(json.loads(json.dumps(next(b for b in bodies if b)))).t_s)
