"""``demtrack import-dem --geoid egm96|FILE|none``: the new site's vertical datum, for real.

Orthometric UTM tiles are made from an ellipsoidal surface minus ``N`` read independently
(rasterio + numpy, :mod:`geoid_oracle`); the imported DEM must give the ellipsoidal
surface back, and ``site.json`` must state the datum. Mistakes: one line, exit 2, no
site folder left behind.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import rasterio
from affine import Affine
from geoid_oracle import EGM96_DEBIAN, rasterio_bilinear, write_linear_tif
from pyproj import Transformer

from demtrack.cli import main
from demtrack.core.geo import geoid as geoid_mod
from demtrack.core.site.folder import load_site

ANCHOR = (40.3556, -79.6225)
UTM = "EPSG:32617"


def h_true(lon, lat):
    return 320.0 + 500.0 * (lon - ANCHOR[1]) - 700.0 * (lat - ANCHOR[0])


def utm_tile(path, n_of):
    x0, y0 = Transformer.from_crs("EPSG:4326", UTM, always_xy=True).transform(ANCHOR[1], ANCHOR[0])
    transform = Affine(10.0, 0.0, np.floor(x0) - 500.0, 0.0, -10.0, np.floor(y0) + 500.0)
    cols, rows = np.meshgrid(np.arange(100) + 0.5, np.arange(100) + 0.5)
    lon, lat = Transformer.from_crs(UTM, "EPSG:4326", always_xy=True).transform(
        *(transform @ (cols, rows))
    )
    prof = dict(driver="GTiff", width=100, height=100, count=1, dtype="float64", crs=UTM)
    with rasterio.open(path, "w", transform=transform, **prof) as ds:
        ds.write(h_true(lon, lat) - n_of(lat, lon), 1)
    return path


def check_dem(site):
    rng = np.random.default_rng(0)
    lat = ANCHOR[0] + rng.uniform(-0.003, 0.003, 30)
    lon = ANCHOR[1] + rng.uniform(-0.004, 0.004, 30)
    e, n, u = site.frame.to_enu(lat, lon, h_true(lon, lat))
    return float(np.nanmax(np.abs(site.dem.sample(e, n) - u)))


def _import(root, tile, *extra):
    argv = ["import-dem", "--site", str(root), str(tile), "--vertical-datum", "orthometric"]
    try:
        return main([*argv, "--cell", "5", *map(str, extra)])
    except SystemExit as exc:  # argparse's own refusals
        return int(exc.code or 0)


@pytest.mark.skipif(not EGM96_DEBIAN.is_file(), reason="Debian's proj-data is not installed")
def test_new_site_in_egm96(tmp_path, capsys):
    tile = utm_tile(tmp_path / "t.tif", lambda la, lo: rasterio_bilinear(EGM96_DEBIAN, la, lo))
    assert _import(tmp_path / "s", tile, "--geoid", "egm96") == 0
    doc = json.loads((tmp_path / "s" / "site.json").read_text())
    assert doc["vertical_datum"] == {"geoid": "EGM96"}
    site = load_site(tmp_path / "s")
    assert site.geoid.name == "EGM96" and check_dem(site) < 0.01
    n0 = float(rasterio_bilinear(EGM96_DEBIAN, site.frame.lat_deg, site.frame.lon_deg))
    assert doc["geoid_undulation_m"] == pytest.approx(n0, abs=1e-3)
    assert "N from EGM96 (egm96_15.gtx, evaluated at each point)" in capsys.readouterr().out


def test_new_site_with_a_users_grid_copied_in(tmp_path):
    grid = tmp_path / "national.tif"
    write_linear_tif(grid, -30.0 + 40.0 * 79.6225, 40.0, 0.0)
    tile = utm_tile(tmp_path / "t.tif", lambda la, lo: rasterio_bilinear(grid, la, lo))
    assert _import(tmp_path / "s", tile, "--geoid", grid) == 0
    doc = json.loads((tmp_path / "s" / "site.json").read_text())
    assert doc["vertical_datum"] == {
        "geoid": "grid",
        "grid": "geoid/national.tif",
        "name": "national",
    }
    assert (tmp_path / "s" / "geoid" / "national.tif").read_bytes() == grid.read_bytes()
    site = load_site(tmp_path / "s")
    assert check_dem(site) < 0.01
    # The same tile read with one constant N would be off by decimetres at the edges.
    assert _import(tmp_path / "c", tile, "--geoid-undulation", doc["geoid_undulation_m"]) == 0
    assert check_dem(load_site(tmp_path / "c")) > 0.1
    # A second import into the site keeps (and may repeat) its geoid, not another.
    assert _import(tmp_path / "s", tile, "--geoid", tmp_path / "s" / "geoid" / "national.tif") == 0


@pytest.mark.parametrize(
    ("extra", "expect"),
    [
        (["--geoid", "{d}/missing.gtx"], "geoid grid not found: {d}/missing.gtx"),
        (["--geoid", "{d}/junk.gtx"], "PROJ cannot read the geoid grid"),
        ([], "--vertical-datum orthometric needs the tiles' geoid"),
        (["--geoid", "none"], "--vertical-datum orthometric needs the tiles' geoid"),
        (["--geoid", "egm96", "--geoid-undulation", "-33"], "either --geoid or --geoid-undulation"),
        (["--geoid-undulation", "nan"], "--geoid-undulation"),
    ],
)
def test_mistakes_are_one_line_and_leave_nothing(tmp_path, capsys, extra, expect):
    (tmp_path / "junk.gtx").write_bytes(b"junk")
    tile = utm_tile(tmp_path / "t.tif", lambda la, lo: np.zeros_like(la))
    code = _import(tmp_path / "s", tile, *[e.format(d=tmp_path) for e in extra])
    err = capsys.readouterr().err
    assert code == 2 and expect.format(d=tmp_path) in err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "s").exists()


def test_egm96_asked_for_but_not_installed(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(geoid_mod, "default_grid_dirs", lambda: (tmp_path / "nowhere",))
    tile = utm_tile(tmp_path / "t.tif", lambda la, lo: np.zeros_like(la))
    assert _import(tmp_path / "s", tile, "--geoid", "egm96") == 2
    err = capsys.readouterr().err
    assert "egm96_15.gtx is not installed" in err and err.count("\n") == 1
    assert not (tmp_path / "s").exists()


def test_an_existing_site_keeps_its_geoid(tmp_path, capsys):
    tile = utm_tile(tmp_path / "t.tif", lambda la, lo: np.full_like(la, -33.0))
    assert _import(tmp_path / "s", tile, "--geoid-undulation", "-33") == 0
    before = (tmp_path / "s" / "site.json").read_text()
    capsys.readouterr()
    assert _import(tmp_path / "s", tile, "--geoid", "none") == 2
    assert "would disagree" in capsys.readouterr().err
    assert (tmp_path / "s" / "site.json").read_text() == before
