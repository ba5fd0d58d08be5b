"""Fixtures shared across the test tree."""

from __future__ import annotations

from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def sample_site_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sample site, generated once per test session (about 6 s)."""
    from demtrack.samplesite.build import build_sample_site

    return build_sample_site(tmp_path_factory.mktemp("sample") / "site")
