"""MISB ST 0601 (UAS Datalink Local Set) KLV: parse, verify, encode, and map to poses.

A packet is the 16-byte universal key ``06 0E 2B 34 02 0B 01 01 0E 01 03 01 01 00 00 00``,
a BER length (short form below 128, else ``0x80 | n`` and ``n`` big-endian bytes), then
tag-length-value items (tags are BER-OID; every tag read here is below 128, one byte).
Tag 1, the checksum, comes last: the 16-bit sum of every byte from the key's first up to
and including the checksum's own tag and length, even-indexed bytes shifted left 8
(ST 0601 sec. 6.5). A packet whose checksum disagrees is refused.

The items read (ST 0601, Table 1: integer mappings "KLV value -> real"):

====  ============================  =======  ==================================
tag   item                          type     mapping
====  ============================  =======  ==================================
2     precision time stamp          uint64   microseconds since 1970 UTC
5     platform heading              uint16   0..360 deg: ``x * 360 / 65535``
6     platform pitch                int16    +-20 deg: ``x * 40 / 65534``
7     platform roll                 int16    +-50 deg: ``x * 100 / 65534``
13    sensor latitude               int32    +-90 deg: ``x * 180 / (2^32 - 2)``
14    sensor longitude              int32    +-180 deg: ``x * 360 / (2^32 - 2)``
15    sensor true altitude (MSL)    uint16   -900..19000 m: ``x * 19900 / 65535 - 900``
16    sensor horizontal FOV         uint16   0..180 deg: ``x * 180 / 65535``
17    sensor vertical FOV           uint16   0..180 deg: ``x * 180 / 65535``
18    sensor relative azimuth       uint32   0..360 deg: ``x * 360 / (2^32 - 1)``
19    sensor relative elevation     int32    +-180 deg: ``x * 360 / (2^32 - 2)``
20    sensor relative roll          uint32   0..360 deg: ``x * 360 / (2^32 - 1)``
====  ============================  =======  ==================================

Signed items use their most negative value (``0x8000``, ``0x80000000``) as "out of
range": read as None. Encoding rounds to the nearest integer. The tests check these
mappings against the standard's published example values (e.g. tag 5 ``71 C2`` is
159.9744 deg, tag 13 ``55 95 B6 6D`` is 60.1768229669783 deg).

Tag 15 is the sensor's altitude above mean sea level (orthometric): :func:`to_pose_sample`
adds the site geoid's undulation at the sensor's latitude and longitude to get the
ellipsoidal height before converting to the site frame.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping
from dataclasses import dataclass, fields
from typing import Any

from ..errors import VideoError

__all__ = [
    "UAS_LS_KEY",
    "UasDatalink",
    "checksum",
    "encode_uas_datalink",
    "iter_uas_datalink",
    "parse_uas_datalink",
    "to_pose_sample",
]

#: The universal key of the UAS Datalink Local Set.
UAS_LS_KEY = bytes.fromhex("060E2B34020B01010E01030101000000")

_U32 = 2**32 - 1
_S32 = 2**32 - 2
#: tag -> (field, byte length, signed, lo, hi, integer span); value = x * (hi - lo) / span + lo
#: for unsigned, x * (hi - lo) / span for signed (centred on 0).
_MAP: dict[int, tuple[str, int, bool, float, float, int]] = {
    5: ("platform_heading_deg", 2, False, 0.0, 360.0, 65535),
    6: ("platform_pitch_deg", 2, True, -20.0, 20.0, 65534),
    7: ("platform_roll_deg", 2, True, -50.0, 50.0, 65534),
    13: ("sensor_lat_deg", 4, True, -90.0, 90.0, _S32),
    14: ("sensor_lon_deg", 4, True, -180.0, 180.0, _S32),
    15: ("sensor_alt_msl_m", 2, False, -900.0, 19000.0, 65535),
    16: ("sensor_hfov_deg", 2, False, 0.0, 180.0, 65535),
    17: ("sensor_vfov_deg", 2, False, 0.0, 180.0, 65535),
    18: ("sensor_rel_az_deg", 4, False, 0.0, 360.0, _U32),
    19: ("sensor_rel_el_deg", 4, True, -180.0, 180.0, _S32),
    20: ("sensor_rel_roll_deg", 4, False, 0.0, 360.0, _U32),
}


@dataclass(frozen=True)
class UasDatalink:
    """The ST 0601 items demtrack reads from one packet (None where absent).

    ``t_s`` is the precision time stamp (UNIX s UTC); angles in degrees as the standard
    defines them (heading clockwise from true north; relative azimuth clockwise from the
    platform's nose, relative elevation positive up); ``sensor_alt_msl_m`` is above mean
    sea level (orthometric).
    """

    t_s: float | None = None
    platform_heading_deg: float | None = None
    platform_pitch_deg: float | None = None
    platform_roll_deg: float | None = None
    sensor_lat_deg: float | None = None
    sensor_lon_deg: float | None = None
    sensor_alt_msl_m: float | None = None
    sensor_hfov_deg: float | None = None
    sensor_vfov_deg: float | None = None
    sensor_rel_az_deg: float | None = None
    sensor_rel_el_deg: float | None = None
    sensor_rel_roll_deg: float | None = None


def checksum(data: bytes) -> int:
    """ST 0601's 16-bit running sum (even-indexed bytes shifted left 8)."""
    total = 0
    for i, b in enumerate(data):
        total += b << (8 * ((i + 1) % 2))
    return total & 0xFFFF


def _ber_length(data: bytes, i: int) -> tuple[int, int]:
    """(length, index after it) of the BER length at ``data[i]``."""
    if i >= len(data):
        raise VideoError("KLV packet truncated in a length")
    first = data[i]
    if first < 0x80:
        return first, i + 1
    n = first & 0x7F
    if n == 0 or i + 1 + n > len(data):
        raise VideoError("KLV packet has a bad long-form length")
    return int.from_bytes(data[i + 1 : i + 1 + n], "big"), i + 1 + n


def _encode_ber(n: int) -> bytes:
    if n < 0x80:
        return bytes([n])
    body = n.to_bytes((n.bit_length() + 7) // 8, "big")
    return bytes([0x80 | len(body)]) + body


def _decode_value(tag: int, raw: bytes) -> float | None:
    name, size, signed, lo, hi, span = _MAP[tag]
    if len(raw) != size:
        raise VideoError(f"KLV tag {tag} ({name}) has {len(raw)} bytes, expected {size}")
    x = int.from_bytes(raw, "big", signed=signed)
    if signed:
        if x == -(2 ** (8 * size - 1)):
            return None  # "out of range" marker
        return x * (hi - lo) / span
    return x * (hi - lo) / span + lo


def _encode_value(tag: int, value: float) -> bytes:
    name, size, signed, lo, hi, span = _MAP[tag]
    if not (math.isfinite(value) and lo <= value <= hi):
        raise VideoError(f"KLV {name} {value} is outside {lo}..{hi}")
    if signed:
        x = int(round(value * span / (hi - lo)))
    else:
        x = int(round((value - lo) * span / (hi - lo)))
    return x.to_bytes(size, "big", signed=signed)


def parse_uas_datalink(packet: bytes) -> UasDatalink:
    """One UAS Datalink Local Set packet (key included) as :class:`UasDatalink`.

    Raises
    ------
    VideoError
        Not a UAS Datalink LS, truncated, or its checksum (tag 1) is missing or wrong.
    """
    data = bytes(packet)
    if not data.startswith(UAS_LS_KEY):
        raise VideoError("not a MISB ST 0601 packet (unknown universal key)")
    length, start = _ber_length(data, 16)
    end = start + length
    if end > len(data):
        raise VideoError(f"KLV packet truncated: {len(data) - start} of {length} bytes")
    values: dict[str, Any] = {}
    i = start
    seen_checksum = False
    while i < end:
        tag = data[i]
        if tag >= 0x80:
            raise VideoError(f"KLV tag at byte {i} uses a multi-byte tag (not read)")
        n, j = _ber_length(data, i + 1)
        raw = data[j : j + n]
        if j + n > end:
            raise VideoError(f"KLV tag {tag} runs past the packet")
        if tag == 1:
            if n != 2:
                raise VideoError("KLV checksum must be 2 bytes")
            want = checksum(data[:j])
            got = int.from_bytes(raw, "big")
            if want != got:
                raise VideoError(
                    f"KLV checksum mismatch: packet says {got:#06x}, bytes give {want:#06x}"
                )
            seen_checksum = True
        elif tag == 2:
            if n != 8:
                raise VideoError("KLV precision time stamp must be 8 bytes")
            values["t_s"] = int.from_bytes(raw, "big") * 1e-6
        elif tag in _MAP:
            values[_MAP[tag][0]] = _decode_value(tag, raw)
        i = j + n
    if not seen_checksum:
        raise VideoError("KLV packet has no checksum (tag 1)")
    return UasDatalink(**values)


def iter_uas_datalink(data: bytes) -> Iterator[UasDatalink]:
    """Every UAS Datalink LS in ``data`` (several may come back to back in one packet)."""
    i = 0
    data = bytes(data)
    while True:
        k = data.find(UAS_LS_KEY, i)
        if k < 0:
            return
        length, start = _ber_length(data, k + 16)
        yield parse_uas_datalink(data[k : start + length])
        i = start + length


def encode_uas_datalink(sample: UasDatalink | Mapping[str, float | None]) -> bytes:
    """Encode the given items (those not None) as one packet with its checksum."""
    values = (
        {f.name: getattr(sample, f.name) for f in fields(UasDatalink)}
        if isinstance(sample, UasDatalink)
        else dict(sample)
    )
    body = bytearray()
    t = values.get("t_s")
    if t is not None:
        body += bytes([2, 8]) + int(round(t * 1e6)).to_bytes(8, "big")
    by_name = {m[0]: tag for tag, m in _MAP.items()}
    for name, value in values.items():
        if name == "t_s" or value is None:
            continue
        if name not in by_name:
            raise VideoError(f"unknown KLV item {name!r}")
        tag = by_name[name]
        raw = _encode_value(tag, float(value))
        body += bytes([tag, len(raw)]) + raw
    body += bytes([1, 2])  # checksum tag and length, counted in the sum
    head = UAS_LS_KEY + _encode_ber(len(body) + 2)
    crc = checksum(head + bytes(body))
    return head + bytes(body) + crc.to_bytes(2, "big")


def to_pose_sample(d: UasDatalink, frame: Any, geoid: Any, t_s: float | None = None) -> Any:
    """A :class:`~demtrack.core.camera.pose_series.PoseSample` from one packet.

    pan = sensor relative azimuth, tilt = sensor relative elevation, roll = sensor
    relative roll (as -180..180), hfov = sensor HFOV; ``platform_ypr_deg`` from the
    platform heading, pitch and roll; ``position_enu`` from latitude, longitude and the
    MSL altitude made ellipsoidal with the site's geoid (``geoid.to_ellipsoidal``), in
    the site's :class:`~demtrack.core.geo.geodesy.LocalFrame` ``frame``.

    Raises
    ------
    VideoError
        The packet has no time (and none given) or no relative azimuth / elevation.
    """
    from ..camera.pose_series import PoseSample

    when = d.t_s if d.t_s is not None else t_s
    if when is None:
        raise VideoError("KLV packet has no precision time stamp (tag 2)")
    if d.sensor_rel_az_deg is None or d.sensor_rel_el_deg is None:
        raise VideoError("KLV packet has no sensor relative azimuth/elevation (tags 18, 19)")
    roll = 0.0 if d.sensor_rel_roll_deg is None else d.sensor_rel_roll_deg
    if roll > 180.0:
        roll -= 360.0
    ypr = None
    if d.platform_heading_deg is not None:
        ypr = (
            d.platform_heading_deg,
            d.platform_pitch_deg or 0.0,
            d.platform_roll_deg or 0.0,
        )
    position = None
    if None not in (d.sensor_lat_deg, d.sensor_lon_deg, d.sensor_alt_msl_m):
        h_m = float(geoid.to_ellipsoidal(d.sensor_lat_deg, d.sensor_lon_deg, d.sensor_alt_msl_m))
        e, n, u = frame.to_enu(d.sensor_lat_deg, d.sensor_lon_deg, h_m)
        position = (float(e), float(n), float(u))
    return PoseSample(
        float(when),
        float(d.sensor_rel_az_deg),
        float(d.sensor_rel_el_deg),
        hfov_deg=d.sensor_hfov_deg,
        roll_deg=roll,
        position_enu=position,
        platform_ypr_deg=ypr,
    )
