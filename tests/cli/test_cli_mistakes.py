"""Common command-line mistakes: each ends in one line on stderr and exit status 2.

Bad numbers (negative, zero, NaN, infinite, out of range), missing files, files of the
wrong kind or suffix, unknown ids and names, missing or malformed options. The oracle
for each: exit status 2, exactly one line on stderr that starts ``demtrack`` and names
the problem (the ``expect`` text), no traceback, and nothing written where a file was
asked for. The commands run in-process through :func:`demtrack.cli.main` (a traceback
would surface as an exception here); a few also run as the console script.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from demtrack.cli import main

# (argv with {site}, {f} = the files folder, {out} = an output folder; text the line names)
MISTAKES: list[tuple[str, str]] = [
    # import-ortho (the worst: --cell -1 wrote an 8192 x 8192 orthophoto)
    ("import-ortho --site {site} --cell -1 {f}/ortho.tif", "--cell must be a positive"),
    ("import-ortho --site {site} --cell 0 {f}/ortho.tif", "--cell must be a positive"),
    ("import-ortho --site {site} --cell nan {f}/ortho.tif", "--cell must be a finite"),
    ("import-ortho --site {site} --cell abc {f}/ortho.tif", "--cell expected a number"),
    ("import-ortho --site {site} {f}/missing.tif", "missing.tif"),
    ("import-ortho --site {site} {f}/notes.txt", "notes.txt"),
    ("import-ortho --site {site} {f}/fake.tif", "fake.tif"),
    ("import-ortho --site {f}/nosite {f}/fake.tif", "nosite"),
    # import-dem
    ("import-dem --site {out}/s --vertical-datum ellipsoidal {f}/missing.tif", "missing.tif"),
    ("import-dem --site {out}/s --vertical-datum ellipsoidal {f}/fake.tif", "fake.tif"),
    ("import-dem --site {out}/s --vertical-datum ellipsoidal --cell -2 {f}/fake.tif", "--cell"),
    ("import-dem --site {out}/s --vertical-datum ellipsoidal --sigma -1 {f}/fake.tif", "--sigma"),
    (
        "import-dem --site {out}/s --vertical-datum ellipsoidal --bounds 0 0 nan 1 {f}/fake.tif",
        "--bounds",
    ),
    (
        "import-dem --site {out}/s --vertical-datum ellipsoidal --coarse-sigma 0 {f}/fake.tif",
        "--coarse-sigma",
    ),
    ("import-dem --site {out}/s {f}/fake.tif", "--vertical-datum"),
    # import-roads
    ("import-roads --site {site} {f}/missing.geojson", "missing.geojson"),
    ("import-roads --site {site} {f}/notes.txt", "notes.txt"),
    ("import-roads --site {site} {f}/broken.geojson", "broken.geojson"),
    # add-camera
    (
        "add-camera --site {site} --id c9 --position 0 0 nan --vertical-datum ellipsoidal"
        " --az 0 --tilt 0",
        "--position",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --az 0 --tilt 0 --fx -5",
        "--fx",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --az 0 --tilt 0 --width 0",
        "--width",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --az inf --tilt 0",
        "--az",
    ),
    # add-camera's orientation: --az/--tilt/--roll, --opk or --rotation, exactly one
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --fx 1000 --width 640 --height 480 --az 0 --tilt 0 --opk 0 0 0",
        "give the orientation once",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --fx 1000 --width 640 --height 480",
        "give the orientation once",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --fx 1000 --width 640 --height 480 --az 10",
        "--az needs --tilt",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --fx 1000 --width 640 --height 480 --opk 0 0 0 --tilt 5",
        "--tilt and --roll go with --az",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --fx 1000 --width 640 --height 480 --rotation 1 0 0 0 1 0 0 0 2",
        "proper rotation",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --fx 1000 --width 640 --height 480 --rotation 1 0 0",
        "--rotation",
    ),
    (
        "add-camera --site {site} --id c9 --position -79 40 300 --vertical-datum ellipsoidal"
        " --fx 1000 --width 640 --height 480 --opk 0 nan 0",
        "--opk",
    ),
    # geolocate
    ("geolocate --site {site} --sensor cam1 --pixel nan 10", "is outside the"),
    ("geolocate --site {site} --sensor cam1 --pixel ten 10", "--pixel expected a number"),
    ("geolocate --site {site} --sensor cam1 --pixel 10", "--pixel"),
    ("geolocate --site {site} --sensor nope --pixel 10 10", "nope"),
    ("geolocate --site {site} --sensor cam1 --pixel 10 10 --pixel-sigma 0", "--pixel-sigma"),
    ("geolocate --site {site} --sensor cam1 --pixel 10 10 --rule middle", "--rule"),
    ("geolocate --site {f}/nosite --sensor cam1 --pixel 10 10", "nosite"),
    ("geolocate --site {site} --pixel 10 10", "--sensor"),
    # build-dem
    ("build-dem {f}/missing.las -o {out}/d.tif", "missing.las"),
    ("build-dem {f}/pts.npy -o {out}/d.tif --cell -1", "--cell"),
    ("build-dem {f}/pts.npy -o {out}/d.tif --cell inf", "--cell"),
    ("build-dem {f}/pts.npy -o {out}/d.tif --fill-sigma 0", "--fill-sigma"),
    ("build-dem {f}/notes.txt -o {out}/d.tif", "notes.txt"),
    ("build-dem {f}/pts.npy -o {out}/d.png", "d.png"),
    # viewshed
    ("viewshed --site {site} --max-range 0", "--max-range"),
    ("viewshed --site {site} --target-height -1", "--target-height"),
    ("viewshed --site {site} --blind-spots -3", "--blind-spots"),
    ("viewshed --site {site} --min-area nan", "--min-area"),
    ("viewshed --site {site} --sensor nope", "nope"),
    ("viewshed --site {site} -o {out}/coverage.png", "coverage.png"),
    # track, gaps, activity
    ("track --site {site} --detections {f}/missing.jsonl -o {out}/t.geojson", "missing.jsonl"),
    ("track --site {site} --detections {f}/notes.txt -o {out}/t.geojson", "'.txt'"),
    ("track --site {site} --detections {f}/dets.jsonl -o {out}/t.xyz", "'.xyz'"),
    (
        "track --site {site} --detections {f}/dets.jsonl -o {out}/t.geojson --epoch yesterday",
        "yesterday",
    ),
    ("gaps --site {site} --detections {f}/dets.jsonl --max-range -1", "--max-range"),
    ("gaps --site {site} --detections {f}/missing.jsonl", "missing.jsonl"),
    ("activity --site {site} --detections {f}/dets.jsonl --loiter-radius -5", "--loiter-radius"),
    ("activity --site {site} --detections {f}/dets.jsonl --meet-time 0", "--meet-time"),
    (
        "activity --site {site} --detections {f}/dets.jsonl --zones {f}/missing.geojson",
        "missing.geojson",
    ),
    # scenarios and evaluations
    ("scenario --site {site} --name vehicle-run -o {out}/s.jsonl --noise-px -1", "--noise-px"),
    ("scenario --site {site} --name vehicle-run -o {out}/s.jsonl --p-miss 1.5", "--p-miss"),
    ("scenario --site {site} --name vehicle-run -o {out}/s.jsonl --seed -1", "--seed"),
    (
        "scenario --site {site} --name vehicle-run -o {out}/s.jsonl --false-alarms nan",
        "--false-alarms",
    ),
    ("scenario --site {site} --name nope -o {out}/s.jsonl", "--name"),
    # times need a zone (issue 27): one line naming the option
    (
        "scenario --site {site} --name vehicle-run -o {out}/s.jsonl --start 2026-12-01T14:30",
        "--start",
    ),
    ("scenario --site {site} --name vehicle-run -o {out}/s.jsonl --start noon", "--start"),
    (
        "track --site {site} --detections {f}/dets.jsonl -o {out}/t.geojson"
        " --epoch 2026-12-01T14:30:00",
        "--epoch '2026-12-01T14:30:00' has no zone",
    ),
    ("serve --site {site} --replay vehicle-run --start 2026-12-01", "--start"),
    ("scenario --site {site} --name vehicle-run -o {out}/s.xyz", "'.xyz'"),
    ("handoff --site {site} --lead 0", "--lead"),
    ("handoff --site {site} --scenario nope", "nope"),
    ("evaluate-activity --site {site} --seed -1", "--seed"),
    # calibration
    ("calibrate --site {site} --sensor cam1 --gcps {f}/missing.csv", "missing.csv"),
    ("calibrate --site {site} --sensor cam1 --gcps {f}/notes.txt --f-scale 0", "--f-scale"),
    ("calibrate-yaw --site {site} --sensor cam1 --threshold -1", "--threshold"),
    # the server
    ("serve --site {site} --port 70000", "--port"),
    ("serve --site {site} --port -1", "--port"),
    ("serve --site {site} --viser-port 65536", "--viser-port"),
    ("serve --site {site} --speed 0 --replay vehicle-run", "--speed"),
    ("serve --site {site} --speed nan --replay vehicle-run", "--speed"),
    ("serve --site {f}/nosite", "nosite"),
    ("demo --site {site} --port -5", "--port"),
    # the parser itself
    ("nosuchcommand", "nosuchcommand"),
    ("geolocate --site {site} --sensor cam1 --pixel 1 2 --bogus", "--bogus"),
]


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Inputs for the mistakes: text where an image is wanted, a broken GeoJSON, points."""
    f = tmp_path_factory.mktemp("mistakes")
    (f / "notes.txt").write_text("these are not the files you are looking for\n")
    (f / "fake.tif").write_bytes(b"not a GeoTIFF at all\n" * 10)
    (f / "ortho.tif").write_bytes(b"not a GeoTIFF either\n")
    (f / "broken.geojson").write_text('{"type": "FeatureCollection", "features": [')
    rng = np.random.default_rng(0)
    np.save(f / "pts.npy", rng.uniform(0, 10, (200, 3)))
    (f / "dets.jsonl").write_text(
        '{"t": 0.0, "sensor": "cam1", "bbox": [500, 480, 540, 520], "class": "vehicle"}\n'
    )
    return f


@pytest.fixture(scope="module")
def site_copy(sample_site_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A copy of the sample site (a refused command must not change it)."""
    dst = tmp_path_factory.mktemp("mistake-site") / "site"
    shutil.copytree(sample_site_dir, dst, ignore=shutil.ignore_patterns("*.sqlite3*"))
    return dst


def _argv(template: str, site: Path, files: Path, out: Path) -> list[str]:
    return [part.format(site=site, f=files, out=out) for part in template.split()]


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse
        status = int(exc.code or 0)
    return status, capsys.readouterr().err


def test_at_least_forty_mistakes_are_listed() -> None:
    assert len(MISTAKES) >= 40
    assert len({m for m, _ in MISTAKES}) == len(MISTAKES)


@pytest.mark.parametrize(("template", "expect"), MISTAKES, ids=[m for m, _ in MISTAKES])
def test_a_mistake_is_one_line_and_exit_2(
    template: str, expect: str, site_copy: Path, files: Path, tmp_path: Path, capsys
) -> None:
    before = (site_copy / "site.json").read_bytes()
    status, err = _run(_argv(template, site_copy, files, tmp_path), capsys)
    assert status == 2, err
    assert err.endswith("\n") and err.count("\n") == 1, err
    assert err.startswith("demtrack") and "Traceback" not in err, err
    assert expect in err, err
    assert (site_copy / "site.json").read_bytes() == before
    written = [p.name for p in tmp_path.rglob("*") if p.is_file()]
    assert not written, f"a refused command wrote {written}"


@pytest.mark.parametrize(
    "template",
    [
        "import-ortho --site {site} --cell -1 {f}/ortho.tif",
        "import-ortho --site {site} {f}/fake.tif",
        "geolocate --site {site} --sensor nope --pixel 10 10",
    ],
)
def test_the_console_script_prints_one_line_too(
    template: str, site_copy: Path, files: Path, tmp_path: Path
) -> None:
    argv = _argv(template, site_copy, files, tmp_path)
    proc = subprocess.run(
        [sys.executable, "-m", "demtrack.cli", *argv], capture_output=True, text=True, check=False
    )
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.count("\n") == 1 and "Traceback" not in proc.stderr, proc.stderr
