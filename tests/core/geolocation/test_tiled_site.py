"""A site whose geolocation runs on a tiled DEM gives the in-memory site's fixes, exactly.

The sample site's DEM is rewritten as a tiled DEM of 64-cell blocks and named in the
manifest (``dem_tiled``) with a budget of a few dozen blocks; every sensor's pixels are
geolocated by both sites with every rule and compared field by field, bit for bit
(points, ranges, covariances, the road rule's points through ``TiledDem.sample``).
"""

from __future__ import annotations

import dataclasses
import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from demtrack.core.errors import SiteError
from demtrack.core.site.folder import load_site
from demtrack.core.terrain.tiled_write import tile_geotiff


@pytest.fixture(scope="module")
def tiled_site(sample_site_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("tiled-site") / "site"
    shutil.copytree(sample_site_dir, root)
    doc = json.loads((root / "site.json").read_text())
    tile_geotiff(root / doc["dem"], root / "dem-tiled.tif", tile=64)
    doc["dem_tiled"] = "dem-tiled.tif"
    doc["dem_memory_budget_mb"] = 1
    (root / "site.json").write_text(json.dumps(doc))
    return root


def _same(a: object, b: object) -> bool:
    if dataclasses.is_dataclass(a) and dataclasses.is_dataclass(b):
        return all(_same(getattr(a, f.name), getattr(b, f.name)) for f in dataclasses.fields(a))
    if isinstance(a, tuple | list):
        return isinstance(b, tuple | list) and len(a) == len(b) and all(map(_same, a, b))
    if isinstance(a, np.ndarray | float):
        return bool(np.array_equal(a, b, equal_nan=True))
    return a == b


def test_tiled_site_geolocates_as_the_in_memory_site(
    sample_site_dir: Path, tiled_site: Path
) -> None:
    plain, tiled = load_site(sample_site_dir), load_site(tiled_site)
    assert tiled.tiled_dem is not None and tiled.tiled_budget_bytes == 2**20
    geo_plain, geo_tiled = plain.geolocator(), tiled.geolocator()
    rng = np.random.default_rng(0)
    n_hits = 0
    for sensor in plain.sensors.values():
        cam = sensor.camera
        w, h = cam.intrinsics.width, cam.intrinsics.height
        u, v = rng.uniform(0, w - 1, 300), rng.uniform(0, h - 1, 300)
        for rule in ("first", "all", "road"):
            want = geo_plain.geolocate(cam, u, v, rule=rule)
            got = geo_tiled.geolocate(cam, u, v, rule=rule)
            assert _same(got, want), (sensor.id, rule)
            n_hits += sum(len(g.hits) for g in want)
    assert n_hits > 500
    stats = geo_tiled._tiled.stats  # type: ignore[union-attr]
    assert stats.loads > 0


def test_bad_tiled_dem_entry_is_a_site_error(tiled_site: Path, tmp_path: Path) -> None:
    root = tmp_path / "site"
    shutil.copytree(tiled_site, root)
    doc = json.loads((root / "site.json").read_text())
    doc["dem_tiled"] = doc["dem"]  # a plain GeoTIFF without block min/max
    (root / "site.json").write_text(json.dumps(doc))
    with pytest.raises(SiteError, match="no block min/max"):
        load_site(root)
    doc["dem_tiled"], doc["dem_memory_budget_mb"] = "dem-tiled.tif", -3
    (root / "site.json").write_text(json.dumps(doc))
    with pytest.raises(SiteError, match="dem_memory_budget_mb"):
        load_site(root)
