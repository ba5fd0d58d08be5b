"""Real time on the command line (issue 27): ``scenario --start``, relative files in ``track``.

Oracles: the scenario's own times plus the start (``datetime`` arithmetic), the truth file
moved by the same shift, and ``track``'s one line saying when a file's times look relative.
"""

from __future__ import annotations

import json
from datetime import UTC, datetime

import pytest

from demtrack.cli import main
from demtrack.core.site.folder import load_site
from demtrack.samplesite.scenarios import make_scenario, read_truth_json

pytestmark = pytest.mark.timeout(900)
START = "2026-12-01T15:30:00+01:00"
START_S = datetime(2026, 12, 1, 14, 30, tzinfo=UTC).timestamp()


def test_scenario_start_stamps_detections_and_truth(capsys, sample_site_dir, tmp_path):
    det, truth = tmp_path / "d.jsonl", tmp_path / "truth.json"
    argv = ["scenario", "--site", str(sample_site_dir), "--name", "vehicle-run"]
    assert main([*argv, "--start", START, "-o", str(det), "--truth", str(truth)]) == 0
    out = capsys.readouterr().out
    assert "times: UTC from 2026-12-01T14:30:00.000Z" in out
    sc = make_scenario(load_site(sample_site_dir), "vehicle-run")
    got = [json.loads(line)["t"] for line in det.read_text().splitlines()]
    assert len(got) == len(sc.detections)
    assert max(abs(g - (START_S + d.t_s)) for g, d in zip(got, sc.detections, strict=True)) < 1e-6
    (tr,) = read_truth_json(truth)
    assert abs(tr.t_s[0] - (START_S + sc.truths[0].t_s[0])) < 1e-3

    # tracked: real UTC in the file, no "relative" line
    gpx = tmp_path / "t.gpx"
    argv = ["track", "--site", str(sample_site_dir), "--detections", str(det)]
    assert main([*argv, "--method", "kalman", "-o", str(gpx)]) == 0
    out = capsys.readouterr().out
    assert "look relative" not in out
    assert "<time>2026-12-01T14:30:" in gpx.read_text() and "times are UTC" in gpx.read_text()


def test_track_says_when_times_look_relative(capsys, sample_site_dir, tmp_path):
    det = tmp_path / "d.jsonl"
    argv = ["scenario", "--site", str(sample_site_dir), "--name", "vehicle-run"]
    assert main([*argv, "--start", "1970-01-01T00:00:00Z", "-o", str(det)]) == 0
    capsys.readouterr()
    out_file = tmp_path / "t.geojson"
    argv = ["track", "--site", str(sample_site_dir), "--detections", str(det)]
    assert main([*argv, "--method", "kalman", "-o", str(out_file)]) == 0
    out = capsys.readouterr().out
    assert "times look relative (no epoch declared, all before 2000)" in out
    props = json.loads(out_file.read_text())["features"][0]["properties"]
    assert props["wall_clock"] is False and "session seconds" in props["time"]
