from __future__ import annotations

import numpy as np
import pytest
from pyproj import CRS

from demtrack.core.errors import InputFileError
from demtrack.core.terrain.pointcloud import read_point_cloud


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_and_laz_keep_coordinates_crs_classes_and_returns(tmp_path, suffix, write_las):
    rng = np.random.default_rng(0)
    xyz = np.column_stack(
        [
            rng.uniform(5e5, 5e5 + 100, 500),
            rng.uniform(4.46e6, 4.46e6 + 100, 500),
            rng.uniform(300, 320, 500),
        ]
    )
    classes = rng.choice([1, 2, 5], 500).astype(np.uint8)
    returns = rng.choice([1, 2], 500).astype(np.uint8)
    write_las(tmp_path / f"p{suffix}", xyz, classes, returns)
    cloud = read_point_cloud(tmp_path / f"p{suffix}")
    np.testing.assert_allclose(cloud.xyz, xyz, atol=0.0006)  # 1 mm storage scale
    assert CRS.from_wkt(cloud.crs_wkt).to_epsg() == 32617
    ground = cloud.select(ground_only=True)
    assert len(ground) == int((classes == 2).sum())
    first_ground = cloud.select(ground_only=True, first_returns=True)
    assert len(first_ground) == int(((classes == 2) & (returns == 1)).sum())


def test_selection_needs_las_attributes(tmp_path):
    np.save(tmp_path / "p.npy", np.zeros((3, 3)))
    cloud = read_point_cloud(tmp_path / "p.npy")
    assert cloud.crs_wkt is None
    with pytest.raises(InputFileError, match="ground-only needs classified points"):
        cloud.select(ground_only=True)


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        ("p.las", b"not a las file", "cannot read LAS/LAZ file"),
        ("p.ply", b"x", "unsupported point file p.ply"),
        ("p.csv", b"x,y,z\n", "no points"),
        ("p.csv", b"x,y,z\n1,2\n", "malformed point file"),
    ],
)
def test_bad_files_are_one_line_errors(tmp_path, name, content, message):
    (tmp_path / name).write_bytes(content)
    with pytest.raises(InputFileError, match=message) as err:
        read_point_cloud(tmp_path / name)
    assert "\n" not in str(err.value)
