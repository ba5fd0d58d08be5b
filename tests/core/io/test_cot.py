"""CoT events: CE against Monte Carlo and quadrature, the XML against the schema's rules."""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import integrate, special

from demtrack.core.errors import InputFileError
from demtrack.core.io.cot import (
    CE_PROBABILITY,
    COT_UNKNOWN_M,
    CotEvent,
    circular_error_m,
    cot_type_of,
    event_from_xml,
    event_to_xml,
    iso_utc,
    linear_error_m,
    parse_iso_utc,
    terrain_vertical_variance_m2,
)

T0 = 1_780_000_000.0  # 2026-05-28T20:26:40Z


def _cov(s1, s2, theta):
    r = np.array([[math.cos(theta), -math.sin(theta)], [math.sin(theta), math.cos(theta)]])
    return r @ np.diag([s1**2, s2**2]) @ r.T


# ------------------------------------------------------------------------------------- CE
def test_ce_of_a_circular_error_is_sigma():
    assert CE_PROBABILITY == pytest.approx(0.393469, abs=1e-6)
    assert circular_error_m(np.eye(2) * 4.0) == pytest.approx(2.0, rel=1e-12)
    assert circular_error_m(np.zeros((2, 2))) == 0.0


def test_ce_of_a_line_is_the_1d_quantile():
    # all the error along one axis: P(|x| <= r) = erf(r / (s sqrt 2))
    r = circular_error_m(_cov(3.0, 0.0, 0.7))
    assert math.erf(r / (3.0 * math.sqrt(2))) == pytest.approx(CE_PROBABILITY, abs=1e-9)
    assert r == pytest.approx(3.0 * math.sqrt(2) * special.erfinv(CE_PROBABILITY))
    # and the elliptical integral tends to it (no jump where the line formula takes over)
    for ratio in (1e-3, 1e-5, 1e-8):
        assert circular_error_m(_cov(3.0, 3.0 * ratio, 0.7)) == pytest.approx(r, rel=1e-5)


@pytest.mark.parametrize(("s1", "s2", "theta"), [(5.0, 1.0, 0.3), (20.0, 0.5, 2.0), (2, 1.9, 1)])
def test_ce_holds_its_probability_by_quadrature(s1, s2, theta):
    r = circular_error_m(_cov(s1, s2, theta))
    assert s2 <= r <= s1

    def pdf(y, x):  # in the error ellipse's axes (a circle is rotation invariant)
        return math.exp(-0.5 * (x * x / s1**2 + y * y / s2**2)) / (2 * math.pi * s1 * s2)

    p, _ = integrate.dblquad(
        pdf,
        -r,
        r,
        lambda x: -math.sqrt(max(r * r - x * x, 0)),
        lambda x: math.sqrt(max(r * r - x * x, 0)),
        epsabs=1e-10,
    )
    assert p == pytest.approx(CE_PROBABILITY, abs=1e-6)


def test_ce_holds_its_probability_by_monte_carlo():
    rng = np.random.default_rng(0)
    for _ in range(5):
        a = rng.normal(size=(2, 2)) * rng.uniform(0.5, 10)
        cov = a @ a.T
        r = circular_error_m(cov)
        x = rng.multivariate_normal([0, 0], cov, size=400_000)
        inside = np.mean(np.hypot(x[:, 0], x[:, 1]) <= r)
        assert inside == pytest.approx(CE_PROBABILITY, abs=0.003)  # 4 sigma of the sample


@settings(max_examples=200, deadline=None)
@given(st.floats(0.01, 1000.0), st.floats(0.0, 1.0), st.floats(0.0, math.pi), st.floats(1.01, 3.0))
def test_ce_is_bounded_rotation_invariant_and_scales(s1, ratio, theta, k):
    s2 = s1 * ratio
    r = circular_error_m(_cov(s1, s2, theta))
    assert 0.5138 * s1 - 1e-9 <= r <= s1 * (1 + 1e-9) and r >= s2 * (1 - 1e-9)
    assert r == pytest.approx(circular_error_m(np.diag([s1**2, s2**2])), rel=1e-7)
    assert circular_error_m(_cov(k * s1, k * s2, theta)) == pytest.approx(k * r, rel=1e-7)


@pytest.mark.parametrize(
    "bad", [[[1, 2], [0, 1]], [[1, 0], [0, -1]], [[np.nan, 0], [0, 1]], [1, 2]]
)
def test_bad_covariances_are_refused(bad):
    with pytest.raises(InputFileError):
        circular_error_m(bad)


def test_le_and_terrain_vertical_variance():
    assert linear_error_m(2.25) == 1.5
    assert linear_error_m(math.nan) == COT_UNKNOWN_M and linear_error_m(-1) == COT_UNKNOWN_M
    # flat ground: only the DEM's own error
    assert terrain_vertical_variance_m2(np.eye(2) * 9, (0, 0), 0.04) == pytest.approx(0.04)
    # Monte Carlo on a plane z = g . xy + noise
    rng = np.random.default_rng(1)
    cov, g, var_dem = _cov(6.0, 1.0, 0.4), np.array([0.2, -0.1]), 0.25
    xy = rng.multivariate_normal([0, 0], cov, size=200_000)
    z = xy @ g + rng.normal(0, math.sqrt(var_dem), len(xy))
    assert terrain_vertical_variance_m2(cov, g, var_dem) == pytest.approx(np.var(z), rel=0.01)


# ------------------------------------------------------------------------------------ XML
def _event(**kw):
    base = dict(
        uid="demtrack.track.7",
        type=cot_type_of("vehicle"),
        how="m-f",
        time_s=T0 + 0.25,
        start_s=T0 + 0.25,
        stale_s=T0 + 60.25,
        lat_deg=40.3581234,
        lon_deg=-79.4701234,
        hae_m=310.25,
        ce_m=3.21,
        le_m=0.87,
        callsign="vehicle 7",
        remarks="17T NE 12345 67890",
        course_deg=93.5,
        speed_mps=12.0,
    )
    base.update(kw)
    return CotEvent(**base)


def test_types_tak_users_expect():
    assert cot_type_of("vehicle") == "a-u-G-E-V"
    assert cot_type_of("human") == "a-u-G-U-C-I"
    assert cot_type_of("marker") == "b-m-p-s-m"
    with pytest.raises(InputFileError):
        cot_type_of("boat")


def test_xml_has_every_attribute_the_schema_requires():
    data = event_to_xml(_event())
    assert b"\n" not in data and not data.startswith(b"<?xml")
    root = ET.fromstring(data)
    assert root.tag == "event"
    # the CoT Event schema's required attributes, and their forms
    assert root.attrib["version"] == "2.0"
    for a in ("uid", "type", "how", "time", "start", "stale"):
        assert root.attrib[a]
    assert re.fullmatch(r"[a-z](-[A-Za-z0-9]+)+", root.attrib["type"])
    assert re.fullmatch(r"[hm](-[a-z])*", root.attrib["how"])
    iso = r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{3}Z"
    for a in ("time", "start", "stale"):
        assert re.fullmatch(iso, root.attrib[a])
    assert root.attrib["time"] == "2026-05-28T20:26:40.250Z"
    point = root.find("point")
    assert point is not None and list(root)[0] is point
    for a in ("lat", "lon", "hae", "ce", "le"):
        float(point.attrib[a])
    assert root.find("detail/contact").attrib["callsign"] == "vehicle 7"
    assert root.find("detail/track").attrib == {"course": "93.50", "speed": "12.00"}
    with_decl = event_to_xml(_event(), declaration=True)
    assert with_decl.startswith(b'<?xml version="1.0" encoding="UTF-8"?><event ')
    assert ET.fromstring(with_decl).attrib == root.attrib


def test_round_trip():
    ev = _event()
    back = event_from_xml(event_to_xml(ev))
    assert back.uid == ev.uid and back.type == ev.type and back.how == ev.how
    assert (back.time_s, back.start_s, back.stale_s) == (ev.time_s, ev.start_s, ev.stale_s)
    assert back.lat_deg == pytest.approx(ev.lat_deg, abs=5e-8)
    assert back.lon_deg == pytest.approx(ev.lon_deg, abs=5e-8)
    assert (back.hae_m, back.ce_m, back.le_m) == (ev.hae_m, ev.ce_m, ev.le_m)
    assert (back.callsign, back.remarks, back.course_deg, back.speed_mps) == (
        ev.callsign,
        ev.remarks,
        ev.course_deg,
        ev.speed_mps,
    )
    # escaping: a callsign with XML's special characters survives
    odd = _event(callsign='a<b & "c"', course_deg=None, speed_mps=None)
    again = event_from_xml(event_to_xml(odd))
    assert again.callsign == 'a<b & "c"' and again.course_deg is None
    gone = event_from_xml(event_to_xml(_event(type="t-x-d-d", link_uid="demtrack.x.marker.3")))
    assert gone.link_uid == "demtrack.x.marker.3"
    assert b"<__forcedelete />" in event_to_xml(_event(link_uid="u"))


def test_unknown_errors_are_cots_9999999():
    ev = _event(ce_m=math.inf, le_m=math.nan)
    assert (ev.ce_m, ev.le_m) == (COT_UNKNOWN_M, COT_UNKNOWN_M)
    assert b'ce="9999999.00"' in event_to_xml(ev)


@pytest.mark.parametrize(
    "kw", [{"uid": ""}, {"lat_deg": 91.0}, {"hae_m": math.nan}, {"stale_s": T0 - 1}]
)
def test_bad_events_are_refused(kw):
    with pytest.raises(InputFileError):
        _event(**kw)


@pytest.mark.parametrize(
    "xml",
    [
        b"<nope/>",
        b"<event",
        b'<event version="2.0" uid="a" type="a-u-G" how="m-f"/>',
        b'<event version="1.0" uid="a" type="a" how="m" time="2026-01-01T00:00:00Z"'
        b' start="2026-01-01T00:00:00Z" stale="2026-01-01T00:00:00Z">'
        b'<point lat="0" lon="0" hae="0" ce="1" le="1"/></event>',
        b'<event version="2.0" uid="a" type="a" how="m" time="2026-01-01T00:00:00"'
        b' start="2026-01-01T00:00:00Z" stale="2026-01-01T00:00:00Z">'
        b'<point lat="0" lon="0" hae="0" ce="1" le="1"/></event>',
    ],
)
def test_malformed_xml_is_refused(xml):
    with pytest.raises(InputFileError):
        event_from_xml(xml)


def test_iso_round_trip():
    for t in (0.0, T0, T0 + 0.999):
        assert parse_iso_utc(iso_utc(t)) == pytest.approx(t, abs=5e-4)
    assert parse_iso_utc("2026-05-28T22:26:40+02:00") == T0
