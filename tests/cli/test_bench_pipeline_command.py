"""``demtrack bench pipeline`` at a toy size: the soak's detections into an in-process pipeline."""

from __future__ import annotations

import gc
import re

import pytest

from demtrack.cli import main


def test_bench_pipeline_smoke(capsys, sample_site_dir):
    thresholds = gc.get_threshold()
    argv = ["bench", "pipeline", "--site", str(sample_site_dir), "--copies", "1"]
    assert main([*argv, "--duration", "24", "--every", "10"]) == 0
    out = capsys.readouterr().out
    rows = [line.split() for line in out.splitlines() if re.match(r"^\s+\d+\s+\d+\s+[\d.]+", line)]
    assert len(rows) == 2
    assert all(int(r[1]) > 0 and float(r[2]) > 0 for r in rows)  # detections, us per detection
    assert "one core sustains" in out
    # the server's collector settings were applied for the run only
    assert gc.get_threshold() == thresholds and gc.get_freeze_count() == 0


def test_bench_pipeline_rejects_a_zero_duration(capsys, sample_site_dir):
    argv = ["bench", "pipeline", "--site", str(sample_site_dir), "--duration", "0"]
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    assert "must be positive" in capsys.readouterr().err
