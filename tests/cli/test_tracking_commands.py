"""``demtrack scenario``, ``track`` and ``evaluate`` end to end on the sample site."""

from __future__ import annotations

import json

import pytest

from demtrack.cli import main
from demtrack.core.geolocation.fix_builder import build_fixes
from demtrack.core.site.folder import load_site
from demtrack.core.tracking import evaluate, run_tracker
from demtrack.samplesite.scenarios import make_scenario, read_truth_json


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


@pytest.fixture(scope="module")
def scenario_files(sample_site_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("scenario")
    det, truth = out / "dets.jsonl", out / "truth.json"
    status = main(
        [
            "scenario", "--site", str(sample_site_dir), "--name", "passing-vehicles",
            "-o", str(det), "--truth", str(truth),
        ]
    )  # fmt: skip
    assert status == 0
    return det, truth


def test_scenario_writes_detections_and_truth(scenario_files):
    det, truth = scenario_files
    lines = det.read_text().splitlines()
    assert len(lines) > 500 and json.loads(lines[0])["sensor"].startswith("cam")
    truths = read_truth_json(truth)
    assert [t.target_id for t in truths] == [1, 2] and all(t.cls == "vehicle" for t in truths)


@pytest.mark.parametrize("suffix", [".geojson", ".csv", ".gpx"])
def test_track_writes_each_format(capsys, sample_site_dir, scenario_files, tmp_path, suffix):
    det, _ = scenario_files
    out = tmp_path / f"tracks{suffix}"
    status, text, _ = run(
        capsys, "track", "--site", sample_site_dir, "--detections", det, "--method", "kalman",
        "-o", out,
    )  # fmt: skip
    assert status == 0 and "kalman:" in text and out.stat().st_size > 100
    if suffix == ".geojson":
        doc = json.loads(out.read_text())
        tracks = [f for f in doc["features"] if f["properties"]["kind"] == "track"]
        assert len(tracks) >= 2
        geometry = tracks[0]["geometry"]  # a MultiLineString: one line per run between gaps
        assert geometry["type"] == "MultiLineString"
        lon, lat, _ = geometry["coordinates"][0][0]
        assert 40.3 < lat < 40.4 and -79.7 < lon < -79.5


def test_evaluate_prints_a_row_per_method_and_plots(capsys, sample_site_dir, tmp_path):
    png = tmp_path / "plot.png"
    status, text, _ = run(
        capsys, "evaluate", "--site", sample_site_dir, "--scenario", "passing-vehicles",
        "--methods", "raw-first", "kalman", "--plot", png,
    )  # fmt: skip
    assert status == 0
    assert "| raw-first |" in text and "| kalman |" in text and "RMSE (m)" in text
    assert png.read_bytes()[:4] == b"\x89PNG"
    # the live server's tracks of the same detections, at 1x and 10x batching
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if "|" in line}
    assert {"server 1x (kalman)", "server 10x (kalman)"} <= set(rows)
    head = [c.strip() for c in rows["method"].split("|")]
    col = head.index("stubs < 5 s")
    for name in ("kalman", "server 1x (kalman)", "server 10x (kalman)"):
        assert rows[name].split("|")[col].strip() == "0", rows[name]
    assert rows["server 1x (kalman)"].split("|")[col + 1].strip() == "0"  # ended early
    assert rows["raw-first"].split("|")[col + 1].strip() == "-"


def test_evaluate_scores_the_server_pipeline_like_offline_kalman(capsys, sample_site_dir):
    status, text, _ = run(
        capsys, "evaluate", "--site", sample_site_dir, "--scenario", "vehicle-run",
        "--methods", "kalman",
    )  # fmt: skip
    assert status == 0
    rows = {
        line.split("|")[1].strip(): line.split("|") for line in text.splitlines() if "|" in line
    }
    head = [c.strip() for c in rows["method"]]
    tracks, stubs = head.index("tracks (false)"), head.index("stubs < 5 s")
    frag = head.index("fragmentation")
    for name in ("kalman", "server 1x (kalman)", "server 10x (kalman)"):
        # one vehicle: one track, none false, no stub, not fragmented
        assert rows[name][tracks].strip() == "1 (0)", rows[name]
        assert rows[name][stubs].strip() == "0" and rows[name][frag].strip() == "0"


def test_evaluate_without_the_server_rows(capsys, sample_site_dir):
    status, text, _ = run(
        capsys, "evaluate", "--site", sample_site_dir, "--scenario", "pedestrians",
        "--methods", "kalman", "--server-method", "none",
    )  # fmt: skip
    assert status == 0 and "| kalman |" in text and "server" not in text


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["track", "--detections", "nope.jsonl", "-o", "t.geojson"], "nope.jsonl: No such file"),
        (["track", "--detections", "d.txt", "-o", "t.geojson"], "unknown detection file type"),
        (["track", "--detections", "d.jsonl", "-o", "t.shp"], "unknown track file type"),
        (["scenario", "--name", "vehicle-run", "-o", "d.txt"], "unknown detection file type"),
        (["scenario", "--name", "vehicle-run", "-o", "d.jsonl", "--p-miss", "2"], "--p-miss"),
        (["evaluate", "--scenario", "pedestrians", "--methods", "psychic"], "unknown method"),
    ],
)
def test_bad_input_is_one_line_and_status_2(capsys, sample_site_dir, tmp_path, argv, message):
    (tmp_path / "d.txt").write_text("")
    (tmp_path / "d.jsonl").write_text("")
    argv = [str(tmp_path / a) if a.startswith(("nope", "d.", "t.")) else a for a in argv]
    status, out, err = run(capsys, argv[0], "--site", sample_site_dir, *argv[1:])
    assert status == 2
    assert message in err and err.count("\n") == 1 and err.startswith(f"demtrack {argv[0]}:")


def test_track_skips_bad_records_with_counts(capsys, sample_site_dir, tmp_path):
    det = tmp_path / "d.csv"
    det.write_text(
        "t,sensor,u_min,v_min,u_max,v_max,class\n"
        "1.0,cam1,600,500,660,540,vehicle\n"
        "1.1,cam9,600,500,660,540,vehicle\n"
        "1.2,cam1,600,500,660,nan,vehicle\n"
        "0.5,cam1,600,500,660,540,vehicle\n"
        "1.3,cam1,600,500,660,5000,vehicle\n"
    )
    status, text, _ = run(
        capsys, "track", "--site", sample_site_dir, "--detections", det, "-o", tmp_path / "t.csv"
    )
    assert status == 0
    assert "1 of 5 detections accepted" in text
    for reason in ("unknown_sensor=1", "nan=1", "time_backwards=1", "outside_image=1"):
        assert reason in text


def test_vehicle_run_accuracy(sample_site_dir):
    """The default vehicle run: the issue's bars for the best method; raw-first jumps.

    Best method ``kalman``: RMSE under 1 m, one track (no phantom stub at the hand-offs:
    issue 26) and one identity from start to end (across the hand-offs and the 11 s
    occlusion on the north bend). Jumps: none into the trees or at the start; since the
    phantoms that used to take them are gone, cam1's crown-raised boxes at 46-47 s and
    89-90 s (near hits 4-9 m off along the ray) pull the car's own track 3.1-3.9 m off
    for 12 points (docs/trajectories.md, "Phantom vehicles").
    """
    site = load_site(sample_site_dir)
    sc = make_scenario(site, "vehicle-run")
    fixes, _ = build_fixes(site, sc.detections)
    raw = evaluate(run_tracker(fixes, "raw-first"), sc.truths)
    best = evaluate(run_tracker(fixes, "kalman", roads=site.roads), sc.truths)
    assert best.rmse_m < 1.0
    assert best.n_jumps <= 12
    assert (best.n_tracks, best.n_false_tracks) == (1, 0)
    assert best.id_switches == 0 and best.fragmentation == 0
    assert best.coverage > 0.85
    assert raw.n_jumps > 100 and raw.rmse_m > 3 * best.rmse_m
