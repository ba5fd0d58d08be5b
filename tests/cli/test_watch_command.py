"""``demtrack watch`` to JSON Lines: the file ``demtrack track`` reads, the batch keys, KLV
poses beside it, and one-line errors for bad input."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "core" / "video"))
from synth import START, Body, klv_clip, site_clip  # noqa: E402

from demtrack.cli import main  # noqa: E402
from demtrack.commands.watch import batch_key  # noqa: E402
from demtrack.core.site.folder import load_site  # noqa: E402

pytestmark = pytest.mark.timeout(600)


@pytest.fixture(scope="module")
def clip(sample_site_dir, tmp_path_factory):
    site = load_site(sample_site_dir)
    bodies = [
        Body("human", (300, 560), (1.4, 0.3), (0.55, 0.35, 1.75), frames=(4, 10**9)),
        Body("vehicle", (900, 500), (-6.0, 2.0), (1.8, 4.5, 1.5), grey=200, frames=(4, 10**9)),
    ]
    return site_clip(tmp_path_factory.mktemp("watch") / "cam1.mp4", site, "cam1", bodies)


def test_watch_writes_jsonl_that_track_reads(sample_site_dir, clip, tmp_path, capsys):
    out = tmp_path / "dets.jsonl"
    args = ["watch", "--site", str(sample_site_dir), "--sensor", "cam1"]
    assert main([*args, "--source", str(clip.path), "-o", str(out)]) == 0
    printed = capsys.readouterr()
    assert "frames/s" in printed.out and "detections/s" in printed.out
    recs = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(recs) > 60
    assert {r["class"] for r in recs} == {"human", "vehicle"}
    assert all(r["sensor"] == "cam1" and START <= r["t"] < START + 3 for r in recs)
    assert [r["t"] for r in recs] == sorted(r["t"] for r in recs)
    tracks = tmp_path / "tracks.geojson"
    cmd = ["track", "--site", str(sample_site_dir), "--detections", str(out)]
    assert main([*cmd, "--method", "kalman", "-o", str(tracks)]) == 0
    assert f"{len(recs)} of {len(recs)} detections accepted" in capsys.readouterr().out
    feats = json.loads(tracks.read_text())["features"]
    assert len({f["properties"].get("track_id", f.get("id")) for f in feats}) >= 2


def test_batch_keys_are_deterministic():
    a = batch_key("cam1", "/data/a.mp4", 25)
    assert a == batch_key("cam1", "/data/a.mp4", 25)
    assert a != batch_key("cam1", "/data/a.mp4", 50) != batch_key("cam2", "/data/a.mp4", 25)
    assert a != batch_key("cam1", "/data/b.mp4", 25)
    assert batch_key("cam1", "rtsp://x", 0, "17") != batch_key("cam1", "rtsp://x", 0, "18")
    assert len(batch_key("c" * 60, "rtsp://" + "x" * 500, 10**9, "1" * 13)) <= 200


def sensor_datalinks(site, n: int = 10):
    from demtrack.core.video.klv import UasDatalink

    lat, lon, h = site.frame.lat_deg, site.frame.lon_deg, site.frame.h_m
    return [
        UasDatalink(
            t_s=START + k * 0.04,
            sensor_lat_deg=lat,
            sensor_lon_deg=lon,
            sensor_alt_msl_m=h + 30.0,
            sensor_hfov_deg=40.0,
            sensor_rel_az_deg=100.0 + k,
            sensor_rel_el_deg=-10.0,
        )
        for k in range(n)
    ]


def test_klv_poses_are_written_beside_the_detections(sample_site_dir, tmp_path):
    from demtrack.core.io.pose_io import read_poses

    site = load_site(sample_site_dir)
    path = klv_clip(tmp_path / "fmv.ts", sensor_datalinks(site))
    out = tmp_path / "d.jsonl"
    args = ["watch", "--site", str(sample_site_dir), "--sensor", "cam1", "--source", str(path)]
    assert main([*args, "--start", "2026-11-18T09:46:40Z", "-o", str(out), "--quiet"]) == 0
    poses = [json.loads(line) for line in (tmp_path / "d.poses.jsonl").read_text().splitlines()]
    assert [p["pan_deg"] for p in poses] == pytest.approx([100.0 + k for k in range(10)], abs=1e-6)
    assert all(p["tilt_deg"] == pytest.approx(-10.0, abs=1e-6) for p in poses)
    assert [p["t"] for p in poses] == pytest.approx([START + k * 0.04 for k in range(10)], abs=1e-6)
    # the file is a pose telemetry file demtrack reads (core.io.pose_io)
    series, report = read_poses(tmp_path / "d.poses.jsonl", sensors={"cam1"})
    assert report.n_records == 10 and len(series["cam1"].samples()) == 10
    # MSL + the site's geoid N = ellipsoidal; 30 m above the anchor's orthometric height
    n_m = float(site.geoid.undulation_m(site.frame.lat_deg, site.frame.lon_deg))
    assert poses[0]["u_m"] == pytest.approx(30.0 + n_m, abs=0.31)


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--source", "none.mp4", "-o", "x.jsonl"], "video file not found: none.mp4"),
        (["--source", "CLIP", "-o", "x.csv"], "written as .jsonl"),
        (["--source", "CLIP"], "give --server URL"),
        (["--source", "CLIP", "-o", "x.jsonl", "--detector", "yolo"], "unknown detector"),
        (["--source", "CLIP", "-o", "x.jsonl", "--start", "2026-11-18T09:46:40"], "zone"),
        (["--source", "CLIP", "-o", "x.jsonl", "--detector", "onnx:none.onnx"], "not found"),
    ],
)
def test_mistakes_are_one_line(
    sample_site_dir, clip, tmp_path, monkeypatch, capsys, extra, message
):
    monkeypatch.chdir(tmp_path)
    extra = [str(clip.path) if e == "CLIP" else e for e in extra]
    rc = main(["watch", "--site", str(sample_site_dir), "--sensor", "cam1", *extra])
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert message in err and "\n" not in err and "Traceback" not in err
