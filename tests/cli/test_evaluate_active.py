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
        assert main([*argv, "--methods", "kalman", "multi-hypothesis-road", "--json"]) == 0
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
