"""``demtrack activity`` end to end: tracked zone crossings match the ground truth's."""

from __future__ import annotations

import json

import numpy as np

from demtrack.cli import main
from demtrack.core.activity.zones import Zone, detect_zone_crossings
from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import read_truth_json


def test_activity_finds_the_truths_zone_crossings_and_no_false_convoy(
    capsys, sample_site_dir, tmp_path
):
    det, truth_path = tmp_path / "dets.jsonl", tmp_path / "truth.json"
    assert (
        main(
            [
                "scenario",
                "--site",
                str(sample_site_dir),
                "--name",
                "passing-vehicles",
                "-o",
                str(det),
                "--truth",
                str(truth_path),
            ]
        )
        == 0
    )
    truths = read_truth_json(truth_path)
    site = load_site(sample_site_dir)
    # A 40 m square zone around where the first vehicle is half-way through its run.
    t = truths[0]
    centre = t.p_enu[len(t.p_enu) // 2, :2]
    corners = centre + np.array([[-20, -20], [20, -20], [20, 20], [-20, 20], [-20, -20]])
    lat, lon, _ = site.frame.to_geodetic(corners[:, 0], corners[:, 1], np.zeros(5))
    ring = [[float(a), float(b)] for a, b in zip(lon, lat, strict=True)]
    zones = {
        "type": "FeatureCollection",
        "features": [
            {
                "type": "Feature",
                "properties": {"name": "checkpoint"},
                "geometry": {"type": "Polygon", "coordinates": [ring]},
            }
        ],
    }
    (tmp_path / "zones.geojson").write_text(json.dumps(zones))
    capsys.readouterr()
    status = main(
        [
            "activity",
            "--site",
            str(sample_site_dir),
            "--detections",
            str(det),
            "--zones",
            str(tmp_path / "zones.geojson"),
            "--json",
        ]
    )
    out = capsys.readouterr().out
    assert status == 0
    events = json.loads(out[out.index("[") :])
    # Passing each other in opposite directions is neither a convoy nor a rendezvous.
    assert not [e for e in events if e["kind"] in ("convoy", "rendezvous")]
    from shapely import Polygon

    truth_events = detect_zone_crossings(truths, [Zone("checkpoint", Polygon(corners))])
    got = sorted((e["kind"], e["t_start_s"]) for e in events if e["kind"].startswith("zone"))
    want = sorted((e.kind, e.t_start_s) for e in truth_events)
    assert len(want) >= 2 and [k for k, _ in got] == [k for k, _ in want]
    assert np.allclose([t for _, t in got], [t for _, t in want], atol=1.5)


def test_handoff_scores_each_scenario(capsys, sample_site_dir):
    assert main(["handoff", "--site", str(sample_site_dir), "--scenario", "vehicle-run"]) == 0
    out = capsys.readouterr().out
    row = next(line for line in out.splitlines() if line.startswith("vehicle-run"))
    handoffs, right = (int(x) for x in row.split()[2:4])
    # The vehicle run crosses between cameras several times; most are predicted right.
    assert handoffs >= 3 and right / handoffs >= 0.5
