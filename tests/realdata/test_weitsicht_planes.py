"""demtrack against weitsicht on its plane cases: drone photos over the sea (0 m EGM96).

The poses come from EXIF/XMP (weitsicht's own conversion to UTM 36N grid axes and
ellipsoidal heights, as ``cases.json`` gives them). demtrack has no plane mapper; a user
gives it a flat DEM, here a GeoTIFF in UTM 36N at the median ellipsoidal height of the
peer's plane hits (``--vertical-datum ellipsoidal``). Measured (docs/real-data.md):

* camera model: demtrack's rays, cut analytically with each point's own plane height in
  the UTM grid frame as weitsicht does, reproduce its points to <= 0.1 mm (JSON rounding).
* site path: weitsicht's plane is 0 m EGM96, whose ellipsoidal height varies by 0.5 mm
  (DSC00316) to 7 mm (dugong) over a footprint, and it treats the UTM grid as Cartesian
  (scale factor 0.99989 at 1.6 deg from the central meridian); the flat site DEM holds
  one height. Together <= 2 cm horizontally and <= 5 mm vertically.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest
from weitsicht_peer import (
    DATA_DIR,
    build_site,
    differences,
    load_plane_cases,
    plane_hits,
    rays_in_grid_axes,
    site_hits_in_dem_crs,
    write_plane_dem,
)

pytestmark = pytest.mark.skipif(
    not (DATA_DIR / "cases.json").is_file(), reason=f"weitsicht data ({DATA_DIR}) not installed"
)

_KEYS = [c.key for c in load_plane_cases(Path("."))] if (DATA_DIR / "cases.json").is_file() else []


@pytest.fixture(scope="module")
def planes(tmp_path_factory: pytest.TempPathFactory):
    """Each plane case with its flat DEM and its site."""
    base = tmp_path_factory.mktemp("planes")
    out = {}
    for case in load_plane_cases(base / "dems"):
        write_plane_dem(case)
        root = build_site(base / case.key.replace("/", "_"), case, 0.0, datum="ellipsoidal")
        out[case.key] = (case, root)
    return out


@pytest.mark.parametrize("key", _KEYS)
def test_demtrack_rays_reproduce_the_peer_on_its_plane(planes, key):
    case, root = planes[key]
    _, site, cam = site_hits_in_dem_crs(root, case)
    _, d_grid = rays_in_grid_axes(site, cam, case)
    err = np.linalg.norm(plane_hits(case.position, d_grid, case.plane_h_m) - case.xyz_peer, axis=1)
    assert err.max() <= 2.5e-4, f"camera model off by {1000 * err.max():.3f} mm"
    # The half-pixel slip moves every point by about half its ground sampling distance.
    shifted = dataclasses.replace(case, pixels=case.pixels + 0.5)
    _, d_shift = rays_in_grid_axes(site, cam, shifted)
    moved = np.hypot(*(plane_hits(case.position, d_shift, case.plane_h_m) - case.xyz_peer)[:, :2].T)
    ratio = moved / (case.gsd_m * math.sqrt(2) / 2)
    assert 0.8 < ratio.min() and ratio.max() < 1.2


@pytest.mark.parametrize("key", _KEYS)
def test_site_path_over_a_flat_dem_against_the_peer(planes, key):
    case, root = planes[key]
    xyz, _, _ = site_hits_in_dem_crs(root, case)
    dh, dv = differences(xyz, case.xyz_peer)
    assert np.isfinite(dh).all()
    assert dh.max() <= 0.02 and dv.max() <= 0.005
