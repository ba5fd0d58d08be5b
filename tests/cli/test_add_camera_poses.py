"""``demtrack add-camera`` with photogrammetric poses (--opk, --rotation) and --k4.

Oracles: the same camera from an OPK triple and from its matrix
(:func:`~demtrack.core.camera.pose.rotation_from_opk_deg`, itself checked against scipy);
``site.json`` keeps ``k4``.
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from demtrack.cli import main
from demtrack.core.camera.pose import rotation_from_opk_deg
from demtrack.core.site.folder import load_site


@pytest.fixture
def site(sample_site_dir: Path, tmp_path: Path) -> Path:
    dst = tmp_path / "site"
    shutil.copytree(sample_site_dir, dst, ignore=shutil.ignore_patterns("*.sqlite3*"))
    return dst


def _position(root: Path) -> list[str]:
    """lon, lat, h (EPSG:4979) 30 m above the DEM's centre."""
    s = load_site(root)
    x0, y0, x1, y1 = s.dem.grid.centre_bounds
    e, n = (x0 + x1) / 2, (y0 + y1) / 2
    u = float(s.dem.sample(np.array([e]), np.array([n]))[0]) + 30.0
    lat, lon, h = (float(v) for v in s.frame.to_geodetic(e, n, u))
    return [repr(lon), repr(lat), repr(h)]


def test_opk_and_rotation_give_one_camera_and_k4_is_kept(site: Path, capsys) -> None:
    common = ["add-camera", "--site", str(site), "--position", *_position(site),
              "--vertical-datum", "ellipsoidal", "--fx", "1000", "--width", "640",
              "--height", "480", "--k1", "-0.05", "--k4", "0.002"]  # fmt: skip
    opk = (4.0, -62.0, 31.0)  # 62 deg off nadir
    assert main([*common, "--id", "a", "--opk", *map(str, opk)]) == 0
    out = capsys.readouterr().out
    assert "east, true north, up at the camera" in out  # a geographic CRS has no grid
    rot = rotation_from_opk_deg(*opk)
    assert main([*common, "--id", "b", "--rotation", *(repr(float(v)) for v in rot.ravel())]) == 0
    s = load_site(site)
    a, b = s.sensor("a").camera, s.sensor("b").camera
    np.testing.assert_allclose(a.R_world_cam, b.R_world_cam, atol=1e-12)
    assert a.intrinsics.k4 == 0.002
    doc = json.loads((site / "site.json").read_text())
    entry = next(x for x in doc["sensors"] if x["id"] == "a")
    assert entry["head"]["intrinsics"]["k4"] == 0.002
