"""Zoom lenses: the ideal zoom, the calibration table's interpolation, its file form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from demtrack.core.camera.pinhole import Intrinsics
from demtrack.core.camera.zoom_lens import (
    ZoomEntry,
    ZoomTable,
    ideal_focal_px,
    intrinsics_for_hfov,
)
from demtrack.core.errors import PoseError

BASE = Intrinsics(1000.0, 1010.0, 640.5, 358.0, 1280, 720, k1=-0.08, k2=0.01, p1=1e-4)


def test_ideal_zoom_spans_the_hfov():
    intr = intrinsics_for_hfov(BASE, 30.0)
    # The image's horizontal edges, -0.5 and W - 0.5, are at +-15 deg for a centred axis.
    half = math.degrees(math.atan((BASE.width / 2) / intr.fx))
    assert half == pytest.approx(15.0)
    assert intr.fy / intr.fx == pytest.approx(BASE.fy / BASE.fx)
    assert (intr.cx, intr.cy, intr.lens_coeffs) == (BASE.cx, BASE.cy, BASE.lens_coeffs)
    with pytest.raises(PoseError, match="hfov"):
        intrinsics_for_hfov(BASE, 180.0)


def table():
    return ZoomTable(
        (
            ZoomEntry(60.0, 1100.0, 1105.0, 641.0, 361.0, k1=-0.2, k2=0.05),
            ZoomEntry(5.0, 14700.0, 14710.0, 646.0, 356.0, k1=0.01),
            ZoomEntry(20.0, 3650.0, 3655.0, 643.0, 359.0, k1=-0.05, p2=2e-4),
        )
    )


def test_entries_come_back_exactly_at_their_hfov():
    tab = table()
    assert [e.hfov_deg for e in tab.entries] == [5.0, 20.0, 60.0]  # sorted
    for e in tab.entries:
        got = tab.intrinsics_at(e.hfov_deg, BASE)
        assert got == e.intrinsics(BASE)
        assert (got.fx, got.cy, got.k1, got.p2) == (e.fx, e.cy, e.k1, e.p2)


def test_interpolation_is_tan_consistent_and_continuous():
    tab = table()
    e0, e1 = tab.entries[1], tab.entries[2]
    h = np.linspace(20.0, 60.0, 41)
    got = [tab.intrinsics_at(x, BASE) for x in h]
    a = (h - 20.0) / 40.0
    # The focal-to-ideal ratio is linear in a; cx and distortion are linear in a.
    ratio = np.array([g.fx / ideal_focal_px(BASE.width, x) for g, x in zip(got, h, strict=True)])
    r0, r1 = e0.fx / ideal_focal_px(1280, 20.0), e1.fx / ideal_focal_px(1280, 60.0)
    np.testing.assert_allclose(ratio, r0 + a * (r1 - r0), rtol=1e-12)
    np.testing.assert_allclose([g.cx for g in got], e0.cx + a * (e1.cx - e0.cx), atol=1e-12)
    np.testing.assert_allclose([g.k1 for g in got], e0.k1 + a * (e1.k1 - e0.k1), atol=1e-15)
    # Continuous at an entry: just inside either side tends to the entry.
    near = tab.intrinsics_at(20.0 + 1e-9, BASE)
    assert near.fx == pytest.approx(e0.fx, rel=1e-9)


def test_a_table_of_ideal_lenses_gives_the_ideal_lens_everywhere():
    ideal = ZoomTable(
        tuple(
            ZoomEntry(h, ideal_focal_px(1280, h), ideal_focal_px(1280, h), 639.5, 359.5)
            for h in (3.0, 25.0, 70.0)
        )
    )
    for h in (3.5, 10.0, 24.9, 47.0):
        assert ideal.intrinsics_at(h, BASE).fx == pytest.approx(ideal_focal_px(1280, h), rel=1e-12)


def test_outside_the_table_is_refused():
    tab = table()
    for h in (4.99, 60.01):
        with pytest.raises(PoseError, match="outside the lens's calibration table"):
            tab.intrinsics_at(h, BASE)
        with pytest.raises(PoseError, match="calibration table"):
            intrinsics_for_hfov(BASE, h, tab)


def test_list_round_trip_and_bad_rows():
    tab = table()
    rows = tab.to_list()
    assert ZoomTable.from_list(rows) == tab
    assert "k4" not in rows[0] and rows[0]["hfov_deg"] == 5.0
    with pytest.raises(PoseError, match="unknown keys"):
        ZoomTable.from_list([{**rows[0], "zoom": 3}])
    with pytest.raises(PoseError, match="missing keys"):
        ZoomTable.from_list([{"hfov_deg": 5.0}])
    with pytest.raises(PoseError, match="two entries"):
        ZoomTable.from_list([rows[0], rows[0]])
    with pytest.raises(PoseError, match="at least one"):
        ZoomTable.from_list([])
    with pytest.raises(PoseError, match="finite"):
        ZoomTable.from_list([{**rows[0], "fx": math.nan}])
    with pytest.raises(PoseError, match="list"):
        ZoomTable.from_list("5,10")
