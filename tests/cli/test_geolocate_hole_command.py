"""``demtrack geolocate``: the DEM-hole warning names the hole and its distance along the ray."""

from __future__ import annotations

import shutil

import numpy as np

from demtrack.cli import main
from demtrack.core.site.folder import load_site
from demtrack.core.site.update import write_dem_atomic
from demtrack.core.terrain.dem import Dem


def test_the_warning_names_the_hole_where_the_ray_met_the_ground(capsys, tmp_path, sample_site_dir):
    root = tmp_path / "site"
    shutil.copytree(sample_site_dir, root)
    site = load_site(root)
    sensor = next(iter(site.sensors.values()))
    cam = sensor.camera
    u, v = cam.intrinsics.width / 2.0, cam.intrinsics.height * 0.8
    before = site.geolocator().geolocate(cam, [u], [v], rule="first")[0]
    assert before.hits and not before.crossed_nodata
    e, n, _ = before.hits[0].p_enu
    # punch a 9 x 9 cell hole centred on the ground point the ray hit
    g = site.dem.grid
    r, c = (int(k[0]) for k in g.cell_of(np.array([e]), np.array([n])))
    elev = np.array(site.dem.elevation)
    elev[r - 4 : r + 5, c - 4 : c + 5] = np.nan
    write_dem_atomic(root / "dem.tif", Dem(g, elev, crs_wkt=site.dem.crs_wkt))
    status = main(["geolocate", "--site", str(root), "--sensor", sensor.id,
                   "--pixel", str(u), str(v), "--rule", "first"])  # fmt: skip
    out = capsys.readouterr().out
    assert status == 0
    line = next(ln for ln in out.splitlines() if "crossed a DEM hole" in ln)
    print(line)
    words = line.replace(",", " ").split()
    e_h, n_h = float(words[words.index("E") + 1]), float(words[words.index("N") + 1])
    along = float(words[words.index("along") - 2])
    # the first hole cell under the ray is at the near edge of the hole, on the ray's way in
    r_h, c_h = (int(k[0]) for k in g.cell_of(np.array([e_h]), np.array([n_h])))
    assert abs(r_h - r) <= 4 and abs(c_h - c) <= 4  # a cell of the punched hole
    assert np.isnan(elev[r_h, c_h])
    assert along < before.hits[0].range_m
    assert before.hits[0].range_m - along < 10 * g.cell_m / 0.05  # a grazing ray at worst
