"""Smoke runs of the benchmarks at toy sizes (they print figures; nothing is timed here)."""

from __future__ import annotations

import shutil

import pytest

from demtrack.cli import main


@pytest.mark.skipif(shutil.which("gdal_viewshed") is None, reason="gdal-bin not installed")
def test_bench_viewshed_smoke(capsys):
    assert main(["bench", "viewshed", "--size", "64", "--check", "50"]) == 0
    out = capsys.readouterr().out
    assert "agrees with dense sampling on 100.00 %" in out and "GDAL:" in out


def test_bench_viewshed_without_gdal_still_reports_demtrack(capsys, monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda _name: None)
    assert main(["bench", "viewshed", "--size", "48", "--check", "20"]) == 0
    assert "gdal_viewshed not found" in capsys.readouterr().out
