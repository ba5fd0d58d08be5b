"""Fixtures: the 12-camera site and a small synthetic archive on it (once per session)."""

from __future__ import annotations

from pathlib import Path

import pytest

from demtrack.reprocess.run import ReprocessSettings, reprocess


@pytest.fixture(scope="session")
def site12_dir(sample_site_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample site with 12 cameras in four clusters (:mod:`demtrack.reprocess.synth`)."""
    from demtrack.reprocess.synth import make_camera_site

    return make_camera_site(sample_site_dir, tmp_path_factory.mktemp("site12") / "site", 12)


@pytest.fixture(scope="session")
def small_archive(site12_dir: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """About 3,000 rendered detections: three copies of two vehicle scenarios."""
    from demtrack.reprocess.synth import synth_archive

    out = tmp_path_factory.mktemp("archive") / "a"
    synth_archive(site12_dir, out, 3000, seeds=1)
    return out


def _run_reprocess(site: Path, archive: Path, out: Path, **kw: object) -> dict:
    settings = ReprocessSettings(**{"method": "multi-hypothesis-road", **kw})  # type: ignore[arg-type]
    return reprocess(str(site), archive, out, settings)


@pytest.fixture(scope="session")
def run_reprocess():
    """``run(site, archive, out, **settings)``: reprocess; returns the manifest."""
    return _run_reprocess


@pytest.fixture(scope="session")
def local_manifest(
    site12_dir: Path, small_archive: Path, tmp_path_factory: pytest.TempPathFactory
) -> dict:
    """The local engine's run of the small archive (the reference of the Dask runs)."""
    return _run_reprocess(site12_dir, small_archive, tmp_path_factory.mktemp("local") / "out")
