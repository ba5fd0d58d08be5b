"""``demtrack evaluate --scenario active-handoff``: the issue's bars, end to end."""

from __future__ import annotations

import contextlib
import io
import json

import pytest

from demtrack.cli import main
from demtrack.commands import choices
from demtrack.commands.evaluate_active import format_comparisons
from demtrack.samplesite.active_scenario import ActiveParams
from demtrack.samplesite.scenarios import ACTIVE_SCENARIOS

FIELDS = ("rmse_m", "p95_m", "jumps", "id_switches", "fragmentation", "in_view_share")


def test_choices_copies_are_current():
    assert choices.ACTIVE_SCENARIO_NAMES == tuple(sorted(ACTIVE_SCENARIOS))
    assert choices.ACTIVE_LATENCY_S == ActiveParams().latency_s


@pytest.fixture(scope="module")
def doc(sample_site_dir):
    """The JSON of one run (module scope: pytest's capsys is per test)."""
    argv = ["evaluate", "--site", str(sample_site_dir), "--scenario", "active-handoff"]
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        methods = ["--methods", "kalman", "multi-hypothesis-road", "--server-method", "none"]
        assert main([*argv, *methods, "--json"]) == 0
    return json.loads(out.getvalue())


def test_every_method_has_the_scenario_fields(doc):
    assert set(doc["methods"]) == {"kalman", "multi-hypothesis-road"}
    for m in doc["methods"].values():
        assert all(k in m for k in FIELDS)


def test_best_method_meets_the_bars(doc):
    best = doc["methods"][doc["best_method"]]
    assert best["rmse_m"] < 1.0
    assert best["jumps"] == 0 and best["id_switches"] == 0
    assert doc["stats"]["handoffs"] >= 3  # identities held across real hand-offs
    assert doc["fix_report"]["skipped"]["no_pose"] == 0


def test_heads_see_more_than_fixed_cameras(doc):
    fixed = doc["comparisons"]["fixed_cameras"]
    assert doc["in_view_share"] > fixed["in_view_share"]
    assert fixed["method"] == doc["best_method"]


def test_ignoring_the_telemetry_ruins_the_fixes(doc):
    c = doc["comparisons"]
    good, stale = c["active"], c["telemetry_ignored"]
    assert stale["fix_median_error_m"] > 10 * good["fix_median_error_m"]
    assert stale["fixes_off_3m_share"] > 0.5 > good["fixes_off_3m_share"]
    assert stale["rmse_m"] is None or stale["rmse_m"] > good["rmse_m"]
    assert stale["no_fix_share"] >= good["no_fix_share"]


def test_ignoring_the_latency_costs_accuracy(doc):
    c = doc["comparisons"]
    assert c["latency_unknown"]["rmse_m"] > c["active"]["rmse_m"]
    assert c["latency_unknown"]["jumps"] > c["active"]["jumps"]


def test_comparison_table_has_a_row_per_run(doc):
    table = format_comparisons(doc).splitlines()
    assert len(table) == 2 + len(doc["comparisons"])
    assert any(line.startswith("| fixed cameras") for line in table)


@pytest.mark.parametrize(
    ("extra", "needle"),
    [(["--latency", "20"], "--latency"), (["--methods", "nope"], "nope")],
)
def test_bad_options_are_one_line(sample_site_dir, capsys, extra, needle):
    argv = ["evaluate", "--site", str(sample_site_dir), "--scenario", "active-handoff", *extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]


def test_scenario_command_writes_the_pose_telemetry_beside_the_detections(
    sample_site_dir, tmp_path, capsys
):
    """The files round-trip: read back, they geolocate every detection at its pose."""
    from demtrack.core.geolocation.fix_builder import build_fixes
    from demtrack.core.io.detections import read_detections
    from demtrack.core.io.pose_io import read_poses
    from demtrack.core.site.folder import load_site
    from demtrack.samplesite.active_scenario import active_site

    out = tmp_path / "run.csv"
    argv = ["scenario", "--site", str(sample_site_dir), "--name", "active-handoff"]
    assert main([*argv, "-o", str(out), "--start", "2026-12-01T14:30:00Z"]) == 0
    assert "pose telemetry" in capsys.readouterr().out
    poses_path = tmp_path / "run.poses.csv"
    poses, report = read_poses(poses_path)
    dets, _ = read_detections(out)
    site = load_site(sample_site_dir)
    assert report.n_skipped == 0 and set(poses) == set(site.sensors)
    t0 = 1796135400.0  # 2026-12-01T14:30:00Z
    for series in poses.values():
        assert series.has_zoom and series.t_s[0] < t0 < series.t_s[-1]
    assert min(d.t_s for d in dets) >= t0
    fixes, fix_report = build_fixes(active_site(site, 0.08), dets, poses=poses)
    assert fix_report.counts["no_pose"] == 0
    assert len(fixes) >= 0.99 * len(dets)
    # Without the telemetry an active sensor's detections are never placed at a stale pose.
    _, blind = build_fixes(active_site(site, 0.08), dets)
    assert blind.counts["no_pose"] == len(dets) and blind.n_fixes == 0


def test_scenario_command_refuses_a_pose_file_type(sample_site_dir, tmp_path, capsys):
    argv = ["scenario", "--site", str(sample_site_dir), "--name", "active-handoff"]
    out = tmp_path / "run.jsonl"
    assert main([*argv, "-o", str(out), "--poses", str(tmp_path / "p.txt")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "'.txt'" in err[0]
    assert not any(tmp_path.iterdir())
