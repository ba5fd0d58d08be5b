"""GCP file conversion (ImGRAFT, CSV with a CRS) and ImGRAFT's camera angles.

Oracles: ImGRAFT's own rotation formula (its ``camera.m``) projecting points, compared with
demtrack's camera built from the converted angles; pyproj for the CRS change; round trips.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pyproj import Transformer

from demtrack.core.camera.gcp_convert import (
    angles_from_imgraft,
    convert_gcps,
    imgraft_rotation,
    imgraft_viewdir,
    read_gcps,
    write_gcp_csv,
)
from demtrack.core.camera.gcp_io import read_gcp_csv
from demtrack.core.camera.pinhole import Camera, Intrinsics
from demtrack.core.errors import CalibrationError, InputFileError

IMGRAFT = """% Ground Control points, IMG_0001
% X,Y,Z    U,V
    445562 7395662 596.4 1951 1490
    445629.5 7395649 581.6  1732.25 1563
445620,7395161,898.2,579,369
"""


def test_imgraft_file_becomes_zero_based_by_exactly_one_pixel(tmp_path):
    (tmp_path / "g.txt").write_text(IMGRAFT)
    gf = read_gcps(tmp_path / "g.txt", "imgraft")
    assert gf.uv.tolist() == [[1950.0, 1489.0], [1731.25, 1562.0], [578.0, 368.0]]
    assert gf.xyz[1].tolist() == [445629.5, 7395649.0, 581.6]
    assert gf.names == ("line3", "line4", "line5") and gf.crs is None


def test_round_trip_through_the_csv_writer(tmp_path):
    (tmp_path / "g.txt").write_text(IMGRAFT)
    gf = convert_gcps(tmp_path / "g.txt", "imgraft", crs="EPSG:32633", vertical="orthometric")
    write_gcp_csv(tmp_path / "out.csv", gf)
    back = read_gcp_csv(tmp_path / "out.csv")
    assert back.crs == "EPSG:32633" and back.vertical == "orthometric"
    np.testing.assert_allclose(back.uv, gf.uv, atol=1e-6)
    np.testing.assert_allclose(back.xyz, gf.xyz, atol=1e-6)
    assert back.names == gf.names
    assert not list(tmp_path.glob("*.part"))
    # The CSV read as 'csv' and written again is byte-identical.
    write_gcp_csv(tmp_path / "again.csv", convert_gcps(tmp_path / "out.csv", "csv"))
    assert (tmp_path / "again.csv").read_bytes() == (tmp_path / "out.csv").read_bytes()


def test_crs_conversion_matches_pyproj(tmp_path):
    rows = ["u,v,x,y,z", "10,20,589312.10,4467321.55,352.1", "30.5,40,590100,4468000,360"]
    (tmp_path / "g.csv").write_text(
        "# crs: EPSG:32617\n# vertical: orthometric\n" + "\n".join(rows)
    )
    gf = convert_gcps(tmp_path / "g.csv", "csv", to_crs="EPSG:4326")
    lon, lat = Transformer.from_crs("EPSG:32617", "EPSG:4326", always_xy=True).transform(
        [589312.10, 590100.0], [4467321.55, 4468000.0]
    )
    np.testing.assert_allclose(gf.xyz[:, 0], lon, atol=1e-12)
    np.testing.assert_allclose(gf.xyz[:, 1], lat, atol=1e-12)
    assert gf.xyz[:, 2].tolist() == [352.1, 360.0]  # 2-D CRSs: heights pass through
    assert gf.crs == "EPSG:4326" and gf.uv[1].tolist() == [30.5, 40.0]


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("1 2 3 4\n", "line 1 must hold five numbers"),
        ("% c\n1 2 3 4+9 5\n", "line 2 must hold five numbers"),
        ("% nothing\n", "has no control points"),
    ],
)
def test_malformed_imgraft_files_are_one_line(tmp_path, text, message):
    (tmp_path / "g.txt").write_text(text)
    with pytest.raises(InputFileError, match=message) as err:
        read_gcps(tmp_path / "g.txt", "imgraft")
    assert "\n" not in str(err.value)


def test_imgraft_without_a_crs_is_refused(tmp_path):
    (tmp_path / "g.txt").write_text(IMGRAFT)
    with pytest.raises(CalibrationError, match="pass --crs"):
        convert_gcps(tmp_path / "g.txt", "imgraft")


def test_imgraft_angles_named_cases():
    assert angles_from_imgraft(math.pi / 2, 0.0, 0.0) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    assert angles_from_imgraft(0.0, 0.0, 0.0)[0] == pytest.approx(90.0)  # east
    assert angles_from_imgraft(0.0, math.radians(10), 0.0)[1] == pytest.approx(-10.0)  # down


@settings(max_examples=60, deadline=None)
@given(st.floats(-math.pi, math.pi), st.floats(-1.4, 1.4), st.floats(-math.pi / 2, math.pi / 2))
def test_imgraft_angles_project_like_imgraft(yaw, pitch, roll):
    intr = Intrinsics(1000.0, 1000.0, 500.0, 400.0, 1001, 801)
    az, tilt, rl = angles_from_imgraft(yaw, pitch, roll)
    cam = Camera.from_azimuth_tilt_roll(intr, [1.0, 2.0, 3.0], az, tilt, rl)
    r = imgraft_rotation(yaw, pitch, roll)
    forward = r[2]
    pts = np.array([1.0, 2.0, 3.0]) + 50.0 * forward + np.array([[0, 0, 0], [3, -2, 1], [-4, 1, 2]])
    p_cam = (pts - [1.0, 2.0, 3.0]) @ r.T  # ImGRAFT: xyz * R'
    u_ig = 1000.0 * p_cam[:, 0] / p_cam[:, 2] + 501.0  # its c is 1-based
    v_ig = 1000.0 * p_cam[:, 1] / p_cam[:, 2] + 401.0
    u, v, _ = cam.project(pts)
    np.testing.assert_allclose(u, u_ig - 1.0, atol=1e-6)
    np.testing.assert_allclose(v, v_ig - 1.0, atol=1e-6)
    back = imgraft_viewdir(az, tilt, rl)
    np.testing.assert_allclose(imgraft_rotation(*back), r, atol=1e-9)
