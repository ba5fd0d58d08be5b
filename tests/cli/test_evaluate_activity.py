"""``demtrack evaluate-activity`` end to end on the sample site."""

from __future__ import annotations

import json

import pytest

from demtrack.cli import main


def run_json(capsys, *argv: str) -> dict:
    capsys.readouterr()
    assert main(["evaluate-activity", *argv, "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_near_miss_case_on_tracks_fires_nothing(capsys, sample_site_dir):
    doc = run_json(capsys, "--site", str(sample_site_dir), "--case", "convoy-short")
    assert doc["method"] == "multi-hypothesis-road" and doc["source"] == "tracks"
    (case,) = doc["cases"]
    # Both cars were tracked and assigned (the chain ran), yet no convoy was reported.
    assert sorted(v for v in case["track_to_target"].values() if v is not None) == [1, 2]
    assert [n["fired"] for n in case["near_misses"]] == [False]
    assert not [e for e in case["detected"] if e["kind"] == "convoy"]
    convoy = next(s for s in doc["scores"] if s["detector"] == "convoy")
    assert convoy["detected"] == 0 and convoy["near_misses_fired"] == 0


def test_loitering_case_on_truth_prints_a_table(capsys, sample_site_dir):
    capsys.readouterr()
    argv = ["evaluate-activity", "--site", str(sample_site_dir), "--case", "loitering"]
    assert main([*argv, "--on-truth"]) == 0
    out = capsys.readouterr().out
    rows = {line.split("|")[1].strip(): line for line in out.splitlines() if line.startswith("| ")}
    # detector | true | detected | found | correct | precision | recall | near-misses fired
    cells = [c.strip() for c in rows["loitering"].split("|")[2:-1]]
    assert cells == ["1", "1", "1", "1", "1.00", "1.00", "0 of 2"]
    zone = [c.strip() for c in rows["zone"].split("|")[2:-1]]
    assert zone[:2] == ["2", "2"] and zone[-1] == "0 of 2"


def test_unknown_case_is_one_clear_error(capsys, sample_site_dir):
    with pytest.raises(SystemExit) as err:
        main(["evaluate-activity", "--site", str(sample_site_dir), "--case", "picnic"])
    assert err.value.code != 0
    assert "invalid choice: 'picnic'" in capsys.readouterr().err
