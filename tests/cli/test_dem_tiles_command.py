"""``demtrack dem tile|synth`` and ``demtrack bench large-dem`` on small DEMs, run for real."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from demtrack.cli import main
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.tiled_dem import TiledDem


def test_tile_the_sample_site_dem(
    capsys: pytest.CaptureFixture[str], sample_site_dir: Path, tmp_path: Path
) -> None:
    doc = json.loads((sample_site_dir / "site.json").read_text())
    src = sample_site_dir / doc["dem"]
    out = tmp_path / "tiled.tif"
    assert main(["dem", "tile", "--dem", str(src), "-o", str(out), "--tile", "128"]) == 0
    assert "tiles 128" in capsys.readouterr().out
    dem, td = Dem.read(src), TiledDem.open(out)
    assert td.tile == 128 and td.bands == 3
    np.testing.assert_array_equal(
        td.read_cells(0, dem.grid.nrows, 0, dem.grid.ncols), dem.elevation
    )


def test_synth_writes_a_tiled_dem(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    out = tmp_path / "s.tif"
    assert (
        main(
            ["dem", "synth", "--size", "700", "--tile", "64", "--compress", "zstd", "-o", str(out)]
        )
        == 0
    )
    assert "700 x 700 cells" in capsys.readouterr().out
    assert TiledDem.open(out).minmax.shape == (11, 11, 2)


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["dem", "tile", "--dem", "missing.tif", "-o", "o.tif"], "does not exist"),
        (["dem", "synth", "--size", "100", "--tile", "100", "-o", "o.tif"], "power of two"),
        (["dem", "synth", "--size", "100", "-o", "o.png"], "--output"),
        (["dem", "synth", "--size", "-3", "-o", "o.tif"], "--size"),
    ],
)
def test_mistakes_are_one_line_errors(
    capsys: pytest.CaptureFixture[str],
    tmp_path: Path,
    monkeypatch: pytest.MonkeyPatch,
    argv: list[str],
    message: str,
) -> None:
    monkeypatch.chdir(tmp_path)
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse's own checks exit; ours return the status
        status = exc.code
    assert status == 2
    err = capsys.readouterr().err
    assert message in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_bench_large_dem_small_run(tmp_path: Path) -> None:
    """In its own process: the peak RSS it prints is the process's lifetime peak."""
    argv = ["bench", "large-dem", "--size", "1500", "--tile", "128", "--cameras", "2"]
    argv += ["--budget-mb", "2048", "--dem", str(tmp_path / "d.tif")]
    code = f"import sys; from demtrack.cli import main; sys.exit(main({argv!r}))"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "budget 2048 MiB: holds" in run.stdout
    lines = run.stdout.splitlines()
    windowed = [ln for ln in lines if ln.startswith("windowed in-memory RayCaster")]
    whole = [ln for ln in lines if ln.startswith("whole DEM, in-memory RayCaster")]
    assert len(windowed) == 1 and "bit-identical" in windowed[0], run.stdout
    assert len(whole) == 1 and "bit-identical" in whole[0], run.stdout
