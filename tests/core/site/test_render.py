from __future__ import annotations

import numpy as np
import pytest

from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import InputFileError
from demtrack.core.site.orthophoto import read_orthophoto, write_orthophoto
from demtrack.core.site.render import SKY_HORIZON, SKY_ZENITH, render_view
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec

RED, BLUE = (200, 20, 20), (20, 20, 200)


def split_world():
    """A flat DEM; an orthophoto red west of x = 0 and blue east of it."""
    grid = GridSpec(-100.0, 100.0, 1.0, 200, 200)
    dem = Dem(grid, np.zeros(grid.shape, np.float32))
    ogrid = GridSpec(-100.0, 100.0, 0.5, 400, 400)
    x, _ = ogrid.centres()
    rgb = np.where((x < 0)[..., None], RED, BLUE).astype(np.uint8)
    return dem, rgb, ogrid


def test_pixels_take_the_colour_of_the_ground_their_ray_hits():
    dem, rgb, ogrid = split_world()
    intr = Intrinsics(60.0, 60.0, 39.5, 29.5, 80, 60)
    cam = Camera.from_azimuth_tilt_roll(intr, [0.0, -60.0, 20.0], 0.0, -10.0, 0.0)
    img = render_view(cam, dem, rgb, ogrid).astype(int)
    # The camera looks north along x = 0: the split runs down the image centre, so
    # left columns see red ground and right columns blue; the top rows see sky.
    ground = img[45:, :, :]
    assert (ground[:, :38, 0] > ground[:, :38, 2]).all()
    assert (ground[:, 42:, 2] > ground[:, 42:, 0]).all()
    sky = img[0, :, :]
    lo, hi = np.minimum(SKY_HORIZON, SKY_ZENITH), np.maximum(SKY_HORIZON, SKY_ZENITH)
    assert ((sky >= lo - 1) & (sky <= hi + 1)).all()


def test_orthophoto_geotiff_round_trip(tmp_path):
    _, rgb, ogrid = split_world()
    write_orthophoto(tmp_path / "o.tif", rgb, ogrid, "EPSG:32617")
    back, grid = read_orthophoto(tmp_path / "o.tif")
    assert grid == ogrid
    np.testing.assert_array_equal(back, rgb)


def test_orthophoto_rejects_wrong_shape_and_unreadable_files(tmp_path):
    _, rgb, ogrid = split_world()
    with pytest.raises(InputFileError, match="orthophoto must be uint8 with shape"):
        write_orthophoto(tmp_path / "o.tif", rgb[:10], ogrid)
    (tmp_path / "bad.tif").write_text("not a tiff")
    with pytest.raises(InputFileError, match="cannot read orthophoto"):
        read_orthophoto(tmp_path / "bad.tif")
