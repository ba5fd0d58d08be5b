"""A site's vertical datum in site.json: EGM96, a grid in the folder, a constant N, or none."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from geoid_oracle import rasterio_bilinear, write_gtx

from demtrack.core.errors import SiteError
from demtrack.core.geo import geoid as geoid_mod
from demtrack.core.geo.geodesy import LocalFrame
from demtrack.core.geo.geoid import EGM96_GRID, GeoidModel, find_grid
from demtrack.core.site.folder import load_site, site_manifest
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

FRAME = LocalFrame(40.3556, -79.6225, 331.0)  # Bushy Run
EGM96_PATH = find_grid(EGM96_GRID)
needs_egm96 = pytest.mark.skipif(EGM96_PATH is None, reason="Debian's proj-data is not installed")


def bare_site(root: Path, **manifest) -> Path:
    root.mkdir(parents=True, exist_ok=True)
    grid = GridSpec(-10.0, 10.0, 1.0, 20, 20)
    Dem(grid, np.zeros(grid.shape, np.float32)).write(root / "dem.tif")
    doc = site_manifest("t", FRAME, [], root, orthophoto=None, roads=None)
    doc.pop("geoid_undulation_m")
    doc.update(manifest)
    (root / "site.json").write_text(json.dumps(doc))
    return root


def test_old_manifests_keep_their_meaning(tmp_path):
    old = load_site(bare_site(tmp_path / "a", geoid_undulation_m=-33.5))
    assert old.geoid == GeoidModel.constant(-33.5) and old.geoid_undulation_m == -33.5
    none = load_site(bare_site(tmp_path / "b", geoid_undulation_m=0.0))
    assert none.geoid.kind == "ellipsoidal" and none.geoid_undulation_m == 0.0
    assert load_site(bare_site(tmp_path / "c")).geoid.kind == "ellipsoidal"


@needs_egm96
def test_egm96_site_and_its_round_trip(tmp_path):
    site = load_site(bare_site(tmp_path / "s", vertical_datum={"geoid": "EGM96"}))
    assert site.geoid.kind == "grid" and site.geoid.name == "EGM96"
    want = float(rasterio_bilinear(EGM96_PATH, np.array(FRAME.lat_deg), np.array(FRAME.lon_deg)))
    assert site.geoid_undulation_m == pytest.approx(want, abs=1e-3)
    assert site.geoid_undulation_m == pytest.approx(-33.97, abs=0.01)
    doc = site_manifest("t", FRAME, [], tmp_path, geoid=site.geoid)
    assert doc["vertical_datum"] == {"geoid": "EGM96"}
    assert doc["geoid_undulation_m"] == pytest.approx(want, abs=1e-3)


def test_a_grid_in_the_site_folder(tmp_path):
    root = bare_site(tmp_path / "s")
    (root / "geoid").mkdir()
    n = np.random.default_rng(4).normal(-33.0, 0.5, (5, 5))
    write_gtx(root / "geoid" / "local.gtx", 40.2, -79.8, 0.1, n)
    doc = json.loads((root / "site.json").read_text())
    doc["vertical_datum"] = {"geoid": "grid", "grid": "geoid/local.gtx", "name": "LOCAL18"}
    (root / "site.json").write_text(json.dumps(doc))
    site = load_site(root)
    assert site.geoid.name == "LOCAL18" and site.geoid.datum == "LOCAL18 geoid"
    lat, lon = np.array([FRAME.lat_deg]), np.array([FRAME.lon_deg])
    assert site.geoid_undulation_m == pytest.approx(
        float(rasterio_bilinear(root / "geoid" / "local.gtx", lat, lon)[0]), abs=1e-5
    )
    again = site_manifest("t", FRAME, [], root, geoid=site.geoid)["vertical_datum"]
    assert again == {"geoid": "grid", "grid": "geoid/local.gtx", "name": "LOCAL18"}
    with pytest.raises(SiteError, match="must be inside the site folder"):
        site_manifest("t", FRAME, [], tmp_path / "elsewhere", geoid=site.geoid)


@pytest.mark.parametrize(
    ("vd", "message"),
    [
        ({"geoid": "grid", "grid": "geoid/missing.gtx"}, "'vertical_datum.grid' file is missing"),
        ({"geoid": "grid", "grid": "../x.gtx"}, "points outside the site folder"),
        ({"geoid": "EGM2008"}, "'geoid' must be EGM96, grid, constant or none, got 'EGM2008'"),
        ({"geoid": "constant"}, "'undulation_m' must be a finite number"),
        ("EGM96", "'vertical_datum' must be an object"),
    ],
)
def test_bad_vertical_datums_are_one_line_errors(tmp_path, vd, message):
    with pytest.raises(SiteError, match=message) as err:
        load_site(bare_site(tmp_path / "s", vertical_datum=vd))
    assert "\n" not in str(err.value)


def test_a_site_asking_for_egm96_without_the_grid_does_not_load(tmp_path, monkeypatch):
    monkeypatch.setattr(geoid_mod, "default_grid_dirs", lambda: (tmp_path / "empty",))
    root = bare_site(tmp_path / "s", vertical_datum={"geoid": "EGM96"})
    with pytest.raises(SiteError, match=r"egm96_15\.gtx is not installed"):
        load_site(root)


def test_a_grid_that_misses_the_site_does_not_load(tmp_path):
    root = bare_site(tmp_path / "s")
    (root / "g").mkdir()
    write_gtx(root / "g" / "far.gtx", 10.0, 10.0, 0.1, np.zeros((3, 3)))
    shutil.copy(root / "g" / "far.gtx", root / "g" / "far2.gtx")
    doc = json.loads((root / "site.json").read_text())
    doc["vertical_datum"] = {"geoid": "grid", "grid": "g/far.gtx"}
    (root / "site.json").write_text(json.dumps(doc))
    with pytest.raises(SiteError, match=r"far\.gtx does not cover 1 point"):
        load_site(root)
