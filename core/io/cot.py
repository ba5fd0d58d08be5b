"""Cursor-on-Target (CoT 2.0) events: tracks and markers as TAK reads them.

An event is ``<event version="2.0" uid type how time start stale><point lat lon hae ce
le/><detail>...</detail></event>`` (MITRE's CoT Event schema, the one ATAK, WinTAK and
TAK Server speak). What goes in:

- ``type``: MIL-STD-2525 in CoT form, affiliation *unknown* (``u``: demtrack sees a
  person or a vehicle, not whose side it is on). A vehicle is ``a-u-G-E-V`` (ground
  equipment, ground vehicle); a person ``a-u-G-U-C-I`` (ground unit, combat, infantry:
  the dismounted-individual symbol 2525B/C has, which ATAK draws for people); an
  operator's marker ``b-m-p-s-m`` (a spot map point).
- ``how``: ``m-f`` (machine, fused: a track estimated from camera fixes) or ``h-e``
  (human entered: a marker).
- ``time`` and ``start``: the moment of the position (ISO 8601 UTC, ``Z``, milliseconds);
  ``stale``: ``time`` plus the sender's interval.
- ``lat``/``lon``: WGS84 degrees; ``hae``: metres above the WGS84 **ellipsoid** (CoT's
  height, not sea level).
- ``ce``: the radius (m) of the circle about the point that holds the horizontal error
  with probability ``1 - exp(-1/2)`` = 39.35 %, the probability of CoT's "circular
  1-sigma" (a circle of radius sigma under a circular normal error). Computed exactly
  from the covariance's eigenvalues (:func:`circular_error_m`), so an elongated error
  ellipse is not reported as its major or its mean axis. ``le``: the vertical 1-sigma
  (m, 68.27 % two-sided). Unknown errors are CoT's ``9999999``.

The detail carries ``contact`` (callsign), ``track`` (course, degrees clockwise from true
north, and speed, m/s) when known, ``remarks`` (MGRS and a free text), and for a delete
(``t-x-d-d``) the ``link`` to the removed uid with ``__forcedelete``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from datetime import UTC, datetime

import numpy as np

from ..errors import InputFileError

__all__ = [
    "CE_PROBABILITY",
    "COT_UNKNOWN_M",
    "CotEvent",
    "circular_error_m",
    "cot_type_of",
    "event_from_xml",
    "event_to_xml",
    "iso_utc",
    "linear_error_m",
    "parse_iso_utc",
    "terrain_vertical_variance_m2",
]

#: CoT's "unknown" for ``ce``/``le`` (m).
COT_UNKNOWN_M = 9_999_999.0
#: The probability ``ce``'s circle holds: that of a circular normal error inside 1 sigma.
CE_PROBABILITY = 1.0 - math.exp(-0.5)

_TYPES = {"vehicle": "a-u-G-E-V", "human": "a-u-G-U-C-I", "marker": "b-m-p-s-m"}
_REQUIRED = ("version", "uid", "type", "how", "time", "start", "stale")
_POINT = ("lat", "lon", "hae", "ce", "le")


def cot_type_of(cls: str) -> str:
    """The CoT type of a track class (``vehicle``, ``human``) or of ``marker``.

    Raises
    ------
    InputFileError
        For any other class.
    """
    try:
        return _TYPES[cls]
    except KeyError:
        raise InputFileError(f"no CoT type for class {cls!r}; known: {', '.join(_TYPES)}") from None


_GL_T, _GL_W = np.polynomial.legendre.leggauss(128)
_SIN = np.sin(_GL_T * (np.pi / 2))
_COS = np.cos(_GL_T * (np.pi / 2))
_W = _GL_W * (np.pi / 2) / math.sqrt(2.0 * np.pi)


def _circle_probability(r: float, s1: float, s2: float) -> float:
    """P(|x| <= r) for a centred normal with axis sigmas ``s1 >= s2 > 0``.

    The integral over the disc's chord along the minor axis is closed (an erf), leaving
    ``int_{-r}^{r} phi(x; s1) erf(sqrt(r^2 - x^2) / (s2 sqrt 2)) dx``; with ``x = r sin t``
    it is smooth and 128-point Gauss-Legendre gives it to ~1e-13 (tested against the
    line limit and 2-D quadrature).
    """
    from scipy.special import erf

    y = r * _COS
    f = np.exp(-0.5 * (r * _SIN / s1) ** 2) * erf(y / (s2 * math.sqrt(2.0))) * y
    return float(_W @ f) / s1


def circular_error_m(cov_en_m2: Sequence[Sequence[float]] | np.ndarray) -> float:
    """CoT ``ce``: radius (m) of the circle holding :data:`CE_PROBABILITY` of the error.

    Parameters
    ----------
    cov_en_m2 : array_like, shape (2, 2)
        Horizontal covariance (east, north) of the position (m^2), symmetric positive
        semi-definite.

    Returns
    -------
    float
        ``sigma`` for an isotropic ``sigma^2 I``; for axis sigmas ``s1 >= s2`` the exact
        radius from the eigenvalues (between ``s2`` and ``s1``); for a degenerate
        (line) error, ``s1 sqrt(2) erfinv(0.3935)`` = 0.5138 ``s1``.

    Raises
    ------
    InputFileError
        For a covariance that is not a finite, symmetric, positive semi-definite 2x2.
    """
    c = np.asarray(cov_en_m2, dtype=np.float64)
    if (
        c.shape != (2, 2)
        or not np.all(np.isfinite(c))
        or abs(c[0, 1] - c[1, 0]) > 1e-9 * (abs(c[0, 0]) + abs(c[1, 1]) + 1e-300)
    ):
        raise InputFileError(f"a horizontal covariance must be a finite symmetric 2x2, got {c!r}")
    lam = np.linalg.eigvalsh(0.5 * (c + c.T))
    if lam[0] < -1e-9 * max(lam[1], 1e-300):
        raise InputFileError(f"horizontal covariance is not positive semi-definite: {lam}")
    s1 = math.sqrt(max(lam[1], 0.0))
    s2 = math.sqrt(max(lam[0], 0.0))
    if s1 == 0.0:
        return 0.0
    if s2 < 1e-9 * s1:  # a line: P(|x| <= r) = erf(r / (s1 sqrt 2))
        from scipy.special import erfinv

        return float(s1 * math.sqrt(2.0) * erfinv(CE_PROBABILITY))
    if s2 > (1 - 1e-12) * s1:
        return s1
    from scipy.optimize import brentq

    return float(
        brentq(lambda r: _circle_probability(r, s1, s2) - CE_PROBABILITY, s2, s1, xtol=1e-9 * s1)
    )


def linear_error_m(var_u_m2: float) -> float:
    """CoT ``le``: the vertical 1-sigma (m) of a vertical variance (m^2), or unknown.

    A non-finite or negative variance gives :data:`COT_UNKNOWN_M`.
    """
    v = float(var_u_m2)
    return math.sqrt(v) if math.isfinite(v) and v >= 0 else COT_UNKNOWN_M


def terrain_vertical_variance_m2(
    cov_en_m2: Sequence[Sequence[float]] | np.ndarray,
    gradient: Sequence[float],
    dem_variance_m2: float,
) -> float:
    """Vertical variance (m^2) of a point on the terrain with horizontal covariance ``C``.

    A ground target lies on the DEM surface ``S``: its height error is the surface's
    slope times its horizontal error plus the DEM's own height error, ``dz = g . dxy +
    dS``, taken as independent: ``g^T C g + var(S)``.

    Parameters
    ----------
    cov_en_m2 : array_like, shape (2, 2)
        Horizontal covariance (m^2).
    gradient : array_like, shape (2,)
        Surface slope ``(dz/dx, dz/dy)`` at the point.
    dem_variance_m2 : float
        Variance of the DEM height there (m^2); NaN (no DEM) gives NaN.
    """
    c = np.asarray(cov_en_m2, dtype=np.float64)
    g = np.asarray(gradient, dtype=np.float64)
    return float(g @ c @ g + float(dem_variance_m2))


def iso_utc(t_s: float) -> str:
    """UNIX seconds as CoT's time: ISO 8601 UTC with milliseconds and ``Z``."""
    text = datetime.fromtimestamp(float(t_s), UTC).isoformat(timespec="milliseconds")
    return text.replace("+00:00", "Z")


def parse_iso_utc(text: str) -> float:
    """CoT's ISO 8601 time (``Z`` or an offset) as UNIX seconds.

    Raises
    ------
    InputFileError
        For a time without a zone or not ISO 8601.
    """
    try:
        dt = datetime.fromisoformat(text.replace("Z", "+00:00"))
    except ValueError:
        raise InputFileError(f"not an ISO 8601 time: {text!r}") from None
    if dt.tzinfo is None:
        raise InputFileError(f"CoT time {text!r} has no zone (expected ...Z)")
    return dt.timestamp()


@dataclass(frozen=True)
class CotEvent:
    """One CoT event.

    Attributes
    ----------
    uid, type, how : str
        Identity (stable per track or marker), CoT type, how the position was found.
    time_s, start_s, stale_s : float
        UNIX seconds (UTC): the position's moment, when it holds from, when it goes stale.
    lat_deg, lon_deg : float
        WGS84.
    hae_m : float
        Height above the WGS84 ellipsoid (m).
    ce_m, le_m : float
        Circular and linear errors (m), as the module docstring defines them.
    callsign : str
        The name TAK shows.
    remarks : str
        Free text (the MGRS reference goes here).
    course_deg, speed_mps : float or None
        Heading clockwise from true north and ground speed, when known.
    link_uid : str or None
        For a delete (type ``t-x-d-d``): the uid of the event it removes (written as
        ``<link uid=... relation="none"/>`` and ``<__forcedelete/>``, as TAK takes it).
    """

    uid: str
    type: str
    how: str
    time_s: float
    start_s: float
    stale_s: float
    lat_deg: float
    lon_deg: float
    hae_m: float
    ce_m: float = COT_UNKNOWN_M
    le_m: float = COT_UNKNOWN_M
    callsign: str = ""
    remarks: str = ""
    course_deg: float | None = None
    speed_mps: float | None = None
    link_uid: str | None = None

    def __post_init__(self) -> None:
        """Validate what a TAK peer would refuse."""
        if not self.uid or not self.type or not self.how:
            raise InputFileError("a CoT event needs a uid, a type and a how")
        for name in ("time_s", "start_s", "stale_s", "lat_deg", "lon_deg", "hae_m"):
            if not math.isfinite(getattr(self, name)):
                raise InputFileError(f"CoT {name} must be finite, got {getattr(self, name)!r}")
        if not (-90 <= self.lat_deg <= 90 and -180 <= self.lon_deg <= 180):
            raise InputFileError(f"CoT point {self.lat_deg}, {self.lon_deg} out of range")
        if not self.start_s <= self.stale_s:
            raise InputFileError("a CoT event cannot go stale before it starts")
        for name in ("ce_m", "le_m"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                object.__setattr__(self, name, COT_UNKNOWN_M)


def _num(v: float, digits: int) -> str:
    return f"{v:.{digits}f}"


def event_to_xml(ev: CotEvent, *, declaration: bool = False) -> bytes:
    """The event as UTF-8 XML, one line, no trailing newline.

    ``declaration``: prefix ``<?xml version="1.0" encoding="UTF-8"?>`` (for a UDP
    datagram; a TCP stream to TAK Server carries bare events back to back).
    Latitude and longitude to 1e-7 degree (1 cm), heights and errors to 0.01 m.
    """
    root = ET.Element(
        "event",
        {
            "version": "2.0",
            "uid": ev.uid,
            "type": ev.type,
            "how": ev.how,
            "time": iso_utc(ev.time_s),
            "start": iso_utc(ev.start_s),
            "stale": iso_utc(ev.stale_s),
        },
    )
    ET.SubElement(
        root,
        "point",
        {
            "lat": _num(ev.lat_deg, 7),
            "lon": _num(ev.lon_deg, 7),
            "hae": _num(ev.hae_m, 2),
            "ce": _num(ev.ce_m, 2),
            "le": _num(ev.le_m, 2),
        },
    )
    detail = ET.SubElement(root, "detail")
    if ev.callsign:
        ET.SubElement(detail, "contact", {"callsign": ev.callsign})
    if ev.course_deg is not None and ev.speed_mps is not None:
        ET.SubElement(
            detail,
            "track",
            {"course": _num(ev.course_deg % 360.0, 2), "speed": _num(ev.speed_mps, 2)},
        )
    if ev.link_uid:
        ET.SubElement(detail, "link", {"uid": ev.link_uid, "relation": "none", "type": "none"})
        ET.SubElement(detail, "__forcedelete")
    if ev.remarks:
        ET.SubElement(detail, "remarks").text = ev.remarks
    body = ET.tostring(root, encoding="unicode", short_empty_elements=True).encode("utf-8")
    return (b'<?xml version="1.0" encoding="UTF-8"?>' + body) if declaration else body


def event_from_xml(data: bytes | str) -> CotEvent:
    """Parse one CoT event (the inverse of :func:`event_to_xml`; for tests and peers).

    Raises
    ------
    InputFileError
        For XML that is not a CoT 2.0 event with every required attribute.
    """
    try:
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise InputFileError(f"not XML: {exc}") from None
    if root.tag != "event":
        raise InputFileError(f"not a CoT event: root element <{root.tag}>")
    missing = [a for a in _REQUIRED if a not in root.attrib]
    point = root.find("point")
    if point is None:
        missing.append("point")
    else:
        missing += [f"point.{a}" for a in _POINT if a not in point.attrib]
    if missing or point is None:
        raise InputFileError(f"CoT event lacks {', '.join(missing)}")
    if root.attrib["version"] != "2.0":
        raise InputFileError(f"CoT version {root.attrib['version']!r}, expected 2.0")
    detail = root.find("detail")
    contact = detail.find("contact") if detail is not None else None
    track = detail.find("track") if detail is not None else None
    remarks = detail.find("remarks") if detail is not None else None
    link = detail.find("link") if detail is not None else None
    try:
        return CotEvent(
            uid=root.attrib["uid"],
            type=root.attrib["type"],
            how=root.attrib["how"],
            time_s=parse_iso_utc(root.attrib["time"]),
            start_s=parse_iso_utc(root.attrib["start"]),
            stale_s=parse_iso_utc(root.attrib["stale"]),
            lat_deg=float(point.attrib["lat"]),
            lon_deg=float(point.attrib["lon"]),
            hae_m=float(point.attrib["hae"]),
            ce_m=float(point.attrib["ce"]),
            le_m=float(point.attrib["le"]),
            callsign=contact.attrib.get("callsign", "") if contact is not None else "",
            remarks=(remarks.text or "") if remarks is not None else "",
            course_deg=float(track.attrib["course"]) if track is not None else None,
            speed_mps=float(track.attrib["speed"]) if track is not None else None,
            link_uid=link.attrib.get("uid") if link is not None else None,
        )
    except (ValueError, KeyError) as exc:
        raise InputFileError(f"malformed CoT event: {exc}") from None
