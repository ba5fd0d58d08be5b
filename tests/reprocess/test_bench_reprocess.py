"""``demtrack bench reprocess`` at a toy size (it prints figures; nothing is timed here)."""

from __future__ import annotations

import pytest

from demtrack.cli import main

pytestmark = pytest.mark.timeout(300)


def test_bench_reprocess_smoke(site12_dir, small_archive, capsys):
    argv = ["bench", "reprocess", "--site12", str(site12_dir), "--archive", str(small_archive)]
    assert main([*argv, "--workers", "1,2"]) == 0
    out = capsys.readouterr().out
    assert "every content hash equals the local run's: yes" in out
    rows = [line for line in out.splitlines() if line.startswith(("local", "dask"))]
    assert [r.split()[:2] for r in rows] == [["local", "-"], ["dask", "1"], ["dask", "2"]]
    assert "1.00x" in rows[1]
