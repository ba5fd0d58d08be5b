"""``demtrack gaps`` on the vehicle run: the crown occlusions come out as occluded by objects."""

from __future__ import annotations

import json

import numpy as np

from demtrack.cli import main
from demtrack.samplesite.world import make_world


def test_vehicle_run_gaps_are_explained(capsys, sample_site_dir, tmp_path):
    det = tmp_path / "dets.jsonl"
    site = str(sample_site_dir)
    # scenario time (t = 0 at the run's start, issue 27's --start): the spans below are in it
    argv = ["scenario", "--site", site, "--name", "vehicle-run", "--start", "1970-01-01T00:00:00Z"]
    assert main([*argv, "-o", str(det)]) == 0
    capsys.readouterr()
    assert main(["gaps", "--site", site, "--detections", str(det), "--json"]) == 0
    captured = capsys.readouterr()
    tracks = json.loads(captured.out)  # stdout holds only the JSON; summaries on stderr
    assert "detections accepted" in captured.err
    gaps = [g for t in tracks for g in t["gaps"]]
    reasons = {g["reason"] for g in gaps}
    assert reasons <= {"outside-fov", "occluded", "missed"} and gaps
    # The three sample cameras cover the whole route (cam3 on its mast sees the east and
    # north sides), so no gap of this run is outside every field of view.
    assert "outside-fov" not in reasons
    trees = make_world(7).trees
    occluded = [g for g in gaps if g["reason"] == "occluded"]
    # The crowns at the loop's south-west corner (cam1, ~24 s) and north side (cam3, the
    # ~11 s occlusion): each blocker is an object high above the ground, inside a crown.
    spans = sorted((g["t_start_s"], g["t_end_s"]) for g in occluded)
    assert len(spans) == 2
    assert spans[0][0] < 25.0 < spans[0][1] and spans[1][1] - spans[1][0] > 8.0
    for g in occluded:
        assert g["shares"]["occluded"] > 0.5
        assert g["blockers"][0]["kind"] == "object"
        for b in g["blockers"]:  # first blocker per (camera, kind)
            if b["kind"] == "object":
                x, y, _ = b["p_enu"]
                assert b["above_ground_m"] > 2.0
                assert min(np.hypot(t.x - x, t.y - y) - t.r_m for t in trees) < 0.5
    assert {g["blockers"][0]["sensor"] for g in occluded} == {"cam1", "cam3"}


def test_missing_detections_file_is_one_clear_error(capsys, sample_site_dir, tmp_path):
    missing = tmp_path / "nope.jsonl"
    status = main(["gaps", "--site", str(sample_site_dir), "--detections", str(missing)])
    err = capsys.readouterr().err
    assert status != 0 and "nope.jsonl" in err and "Traceback" not in err
