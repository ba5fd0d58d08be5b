"""``demtrack import-dem``: no hole strips along warped edges; stated resampling and bounds."""

from __future__ import annotations

import numpy as np
import rasterio
from affine import Affine
from pyproj import Transformer

from demtrack.cli import main
from demtrack.core.site.folder import load_site

UTM = "EPSG:32617"
LAT0, LON0 = 40.3573, -79.6208  # 0.9 deg of meridian convergence in UTM 17N


def run(capsys, *argv):
    status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err


def utm_dem(path):
    x0, y0 = Transformer.from_crs("EPSG:4326", UTM, always_xy=True).transform(LON0, LAT0)
    t = Affine(2.0, 0.0, np.floor(x0) - 200.0, 0.0, -2.0, np.floor(y0) + 200.0)
    r, c = np.mgrid[0:200, 0:200]
    z = (300 + 0.05 * c + 3 * np.sin(r / 15.0)).astype(np.float32)
    with rasterio.open(path, "w", driver="GTiff", height=200, width=200, count=1,
                       dtype="float32", crs=UTM, transform=t) as ds:  # fmt: skip
        ds.write(z, 1)
    return path


def test_default_bounds_leave_no_edge_holes(capsys, tmp_path):
    src = utm_dem(tmp_path / "dem.tif")
    status, out, err = run(
        capsys, "import-dem", "--site", tmp_path / "s", src, "--vertical-datum", "ellipsoidal",
        "--resampling", "cubic",
    )  # fmt: skip
    assert status == 0, err
    assert "largest rectangle inside the warped footprint" in out and "resampling cubic" in out
    dem = load_site(tmp_path / "s").dem
    assert not dem.nodata.any()
    # nearly the whole 400 m x 400 m footprint is kept (it is rotated by only 0.9 deg)
    assert dem.grid.ncols * dem.grid.cell_m > 380 and dem.grid.nrows * dem.grid.cell_m > 380
    assert "0 holes" in out


def test_bounds_as_given_are_kept_and_said(capsys, tmp_path):
    src = utm_dem(tmp_path / "dem.tif")
    status, out, err = run(
        capsys, "import-dem", "--site", tmp_path / "s", src, "--vertical-datum", "ellipsoidal",
        "--bounds", -210, -210, 210, 210, "--cell", 2,
    )  # fmt: skip
    assert status == 0, err
    assert "--bounds as given" in out and "resampling bilinear" in out
    dem = load_site(tmp_path / "s").dem
    assert dem.grid.bounds == (-210.0, -210.0, 210.0, 210.0)
    assert dem.nodata.any()  # past the source's edges: holes, as asked
