"""Markers' GPX waypoints and KML placemarks: EGM96 heights read back by GDAL; clamped KML."""

from __future__ import annotations

import numpy as np
import pyogrio.raw
import pytest
import shapely
from geoid_oracle import EGM96_DEBIAN, egm96_n

from demtrack.core.errors import TrackingError
from demtrack.core.geo.geoid import GeoidModel
from demtrack.core.io.export_common import HeightModel, TimeBase
from demtrack.core.io.export_waypoints import Waypoint, waypoints_gpx, waypoints_kml

pytestmark = pytest.mark.skipif(not EGM96_DEBIAN.is_file(), reason="needs Debian's proj-data")
T0 = 1_714_564_800.0  # 2024-05-01T12:00:00Z


def _points():
    rng = np.random.default_rng(5)
    return [
        Waypoint(f"M{k}", 40.355 + rng.uniform(-1e-3, 1e-3), -79.6225 + rng.uniform(-1e-3, 1e-3),
                 330.0 + rng.uniform(-5, 5), T0 + k, "on the road")
        for k in range(6)
    ]  # fmt: skip


def _read(path, layer=None):
    meta, _, geoms, fields = pyogrio.raw.read(path, layer=layer)
    xyz = np.array([shapely.get_coordinates(shapely.from_wkb(g), include_z=True)[0] for g in geoms])
    return xyz, dict(zip(meta["fields"], fields, strict=True))


def test_marker_heights_are_egm96_and_kml_is_clamped_to_the_ground(tmp_path):
    pts = _points()
    heights = HeightModel.from_geoid(GeoidModel.egm96())
    times = TimeBase(wall_clock=True)
    h = np.array([p.h_m for p in pts])
    want = h - egm96_n([p.lat_deg for p in pts], [p.lon_deg for p in pts])
    kml = tmp_path / "m.kml"
    kml.write_text(waypoints_kml(pts, heights, times, name="m", altitude_mode="clampToGround"))
    xyz, fields = _read(kml)
    np.testing.assert_allclose(xyz[:, 2], want, atol=1e-3)  # written to 1 mm
    assert list(fields["altitudeMode"]) == ["clampToGround"] * len(pts)
    assert "EGM96" in kml.read_text() and "placed on the ground" in kml.read_text()
    gpx = tmp_path / "m.gpx"
    gpx.write_text(waypoints_gpx(pts, heights, times, name="m"))
    _, fields = _read(gpx, "waypoints")
    np.testing.assert_allclose(fields["ele"].astype(float), want, atol=1e-6)
    assert np.all(want - h > 33.0)
    # The default stays absolute; anything else is refused.
    assert "<altitudeMode>absolute</altitudeMode>" in waypoints_kml(pts, heights, times, name="m")
    with pytest.raises(TrackingError, match="altitude_mode"):
        waypoints_kml(pts, heights, times, name="m", altitude_mode="relativeToGround")
