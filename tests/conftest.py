"""Fixtures shared across the test tree."""

from __future__ import annotations

from pathlib import Path

import laspy
import numpy as np
import pytest
from pyproj import CRS


@pytest.fixture(scope="session")
def sample_site_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample site, generated once per test session (about 6 s)."""
    from demtrack.samplesite.build import build_sample_site

    return build_sample_site(tmp_path_factory.mktemp("sample") / "site")


def _write_las(path, xyz, classes, returns, epsg=32617):
    """Write a LAS/LAZ file (by suffix) with a CRS, classes and return numbers."""
    header = laspy.LasHeader(point_format=3, version="1.2")
    header.offsets = xyz.min(axis=0)
    header.scales = [0.001, 0.001, 0.001]
    if epsg:
        header.add_crs(CRS.from_epsg(epsg))
    las = laspy.LasData(header)
    las.x, las.y, las.z = xyz[:, 0], xyz[:, 1], xyz[:, 2]
    las.classification = classes
    las.return_number = returns
    las.number_of_returns = np.maximum(returns, 1)
    las.write(path)


@pytest.fixture
def write_las():
    """``write_las(path, xyz, classes, returns, epsg=32617)``."""
    return _write_las
