"""The sample site states the real Bushy Run's vertical datum, EGM96, and needs its grid."""

from __future__ import annotations

import json

import pytest
from geoid_oracle import EGM96_DEBIAN, egm96_n

from demtrack.core.errors import GeoidError
from demtrack.core.geo import geoid as geoid_mod
from demtrack.samplesite.build import build_sample_site


@pytest.mark.skipif(not EGM96_DEBIAN.is_file(), reason="Debian's proj-data is not installed")
def test_the_sample_site_states_egm96(sample_site_dir):
    doc = json.loads((sample_site_dir / "site.json").read_text())
    assert doc["vertical_datum"] == {"geoid": "EGM96"}
    fr = doc["frame"]
    n0 = float(egm96_n(fr["lat_deg"], fr["lon_deg"]))
    assert doc["geoid_undulation_m"] == pytest.approx(n0, abs=1e-3)
    assert n0 == pytest.approx(-33.97, abs=0.01)


def test_without_the_grid_the_build_stops_before_writing(tmp_path, monkeypatch):
    monkeypatch.setattr(geoid_mod, "default_grid_dirs", lambda: (tmp_path / "nowhere",))
    with pytest.raises(GeoidError, match=r"egm96_15\.gtx is not installed"):
        build_sample_site(tmp_path / "site")
    assert not (tmp_path / "site").exists()
