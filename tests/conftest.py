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


# The real lidar tile: Autzen stadium (Eugene, Oregon), shipped in laspy's source
# distribution on the package registry. Fetched at test time into a cache outside the
# repository (never committed): DEMTRACK_TEST_DATA, else ~/.cache/demtrack-test-data.
LASPY_SDIST = "laspy==2.7.0"
AUTZEN_MEMBER = "laspy-2.7.0/tests/data/autzen_trim.laz"
AUTZEN_SHA256 = "75867b3e75cfc3c2e96da9f753c04c9fbaa6a59468dea13e2859f3109b38bd66"


def fetch_autzen() -> Path:
    """Path of ``autzen_trim.laz``, downloaded with the system ``pip download`` once."""
    import hashlib
    import os
    import shutil
    import subprocess
    import tarfile
    import tempfile

    cache = Path(
        os.environ.get("DEMTRACK_TEST_DATA") or Path.home() / ".cache" / "demtrack-test-data"
    )
    target = cache / "autzen_trim.laz"

    def good(p: Path) -> bool:
        return p.is_file() and hashlib.sha256(p.read_bytes()).hexdigest() == AUTZEN_SHA256

    if good(target):
        return target
    # A source distribution fetched beforehand (.ci/run does), else pip, else uv's pip.
    pip = shutil.which("pip") or shutil.which("pip3")
    uvx = shutil.which("uvx")
    cmd = [pip] if pip else [uvx, "pip"] if uvx else ["pip"]
    cmd += ["download", "--no-deps", "--no-binary", ":all:", LASPY_SDIST]
    cache.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=cache) as tmp:
        sdists = sorted(cache.glob("laspy-2.7.0.tar.gz"))
        if not sdists:
            done = subprocess.run([*cmd, "-d", tmp], capture_output=True, text=True, timeout=300)
            sdists = list(Path(tmp).glob("laspy-*.tar.gz"))
            if done.returncode != 0 or not sdists:
                pytest.fail(
                    f"cannot fetch the Autzen tile: `{' '.join(cmd)}` failed: {done.stderr}"
                )
        with tarfile.open(sdists[0]) as tar:
            member = tar.extractfile(AUTZEN_MEMBER)
            assert member is not None
            part = cache / "autzen_trim.laz.part"
            part.write_bytes(member.read())
        if not good(part):
            pytest.fail(f"{AUTZEN_MEMBER} in {sdists[0].name} does not have the expected sha256")
        part.replace(target)
    return target


@pytest.fixture(scope="session")
def autzen_laz() -> Path:
    """The real Autzen lidar tile (LAZ, Oregon state plane, international feet)."""
    return fetch_autzen()


@pytest.fixture(scope="session")
def postgres_cluster(tmp_path_factory: pytest.TempPathFactory):
    """A real PostgreSQL 15 server (with PostGIS) for the session, on a loopback port.

    Missing binaries skip locally and fail in CI (``CI`` set), where ``.ci/run`` installs them.
    """
    import os

    from postgres_cluster import PostgresCluster, find_pg_bin  # tests/ is on sys.path

    if find_pg_bin() is None:
        if os.environ.get("CI"):
            pytest.fail("PostgreSQL is not installed (apt-get install postgresql-15)")
        pytest.skip("PostgreSQL is not installed (apt-get install postgresql-15)")
    cluster = PostgresCluster(tmp_path_factory.mktemp("pg")).start()
    yield cluster
    cluster.stop()


@pytest.fixture
def postgres_url(postgres_cluster) -> str:
    """A fresh empty database on the session's PostgreSQL server; its URL."""
    return postgres_cluster.create_database()
