"""MISB ST 0601 KLV: the standard's example values, the checksum, and a round trip through
an MPEG-TS that PyAV writes with H.264 video and a KLV data stream."""

from __future__ import annotations

from fractions import Fraction

import av
import numpy as np
import pytest

from demtrack.core.errors import VideoError
from demtrack.core.video.klv import (
    UAS_LS_KEY,
    UasDatalink,
    _decode_value,
    _encode_value,
    checksum,
    encode_uas_datalink,
    iter_uas_datalink,
    parse_uas_datalink,
)
from demtrack.core.video.reader import VideoReader

# (tag, value bytes, real value) from MISB ST 0601's published examples (as quoted in
# the test vectors of the klvdata and KWIVER projects; read there, not copied).
EXAMPLES = [
    (5, "71C2", 159.9744),
    (6, "FD3D", -0.4315),
    (7, "08B8", 3.405814),
    (13, "5595B66D", 60.1768229669783),
    (14, "5B5360C4", 128.426759042045),
    (15, "C221", 14190.72),
    (16, "CD9C", 144.5713),
    (17, "D917", 152.6436),
    (18, "724A0A20", 160.719211474396),
    (19, "87F84B86", -168.792324833941),
    (20, "7DC55ECE", 176.865437690572),
]
# one unit of each item's integer mapping, the most a decoded value may differ by
STEP = {5: 360 / 65535, 6: 40 / 65534, 7: 100 / 65534, 13: 180 / (2**32 - 2),
        14: 360 / (2**32 - 2), 15: 19900 / 65535, 16: 180 / 65535, 17: 180 / 65535,
        18: 360 / (2**32 - 1), 19: 360 / (2**32 - 2), 20: 360 / (2**32 - 1)}  # fmt: skip


@pytest.mark.parametrize(("tag", "hexval", "value"), EXAMPLES)
def test_the_standards_example_values(tag, hexval, value):
    assert _decode_value(tag, bytes.fromhex(hexval)) == pytest.approx(value, abs=STEP[tag])
    assert _encode_value(tag, value).hex().upper() == hexval


def test_precision_time_stamp_example():
    # ST 0601's example: 00 04 60 50 58 4E 01 80 is 2009-01-12T22:08:22Z
    pkt = encode_uas_datalink({"t_s": 1231798102.0})
    assert bytes.fromhex("0208000460505 84E0180".replace(" ", "")) in pkt
    assert parse_uas_datalink(pkt).t_s == 1231798102.0


def bcc16(data: bytes) -> int:
    """The standard's C routine, transcribed: bcc += buff[i] << (8 * ((i + 1) % 2))."""
    bcc = 0
    for i in range(len(data)):
        bcc = (bcc + (data[i] << (8 * ((i + 1) % 2)))) & 0xFFFF
    return bcc


def test_checksum_is_verified():
    pkt = encode_uas_datalink(UasDatalink(t_s=1.8e9, sensor_rel_az_deg=12.5, sensor_rel_el_deg=-8))
    assert pkt.startswith(UAS_LS_KEY)
    assert checksum(pkt[:-2]) == bcc16(pkt[:-2]) == int.from_bytes(pkt[-2:], "big")
    assert pkt[-4:-2] == bytes([1, 2])  # the checksum item comes last
    bad = bytearray(pkt)
    bad[20] ^= 0x01
    with pytest.raises(VideoError, match="checksum"):
        parse_uas_datalink(bytes(bad))
    with pytest.raises(VideoError, match="truncated"):
        parse_uas_datalink(pkt[:30])
    with pytest.raises(VideoError, match="key"):
        parse_uas_datalink(b"\x00" * 40)


def test_round_trip_within_one_step():
    rng = np.random.default_rng(0)
    for _ in range(50):
        d = UasDatalink(
            t_s=1.8e9 + float(rng.integers(0, 10**9)) * 1e-6,
            platform_heading_deg=float(rng.uniform(0, 360)),
            platform_pitch_deg=float(rng.uniform(-20, 20)),
            platform_roll_deg=float(rng.uniform(-50, 50)),
            sensor_lat_deg=float(rng.uniform(-90, 90)),
            sensor_lon_deg=float(rng.uniform(-180, 180)),
            sensor_alt_msl_m=float(rng.uniform(-900, 19000)),
            sensor_hfov_deg=float(rng.uniform(0, 180)),
            sensor_vfov_deg=float(rng.uniform(0, 180)),
            sensor_rel_az_deg=float(rng.uniform(0, 360)),
            sensor_rel_el_deg=float(rng.uniform(-180, 180)),
            sensor_rel_roll_deg=float(rng.uniform(0, 360)),
        )
        back = parse_uas_datalink(encode_uas_datalink(d))
        assert back.t_s == pytest.approx(d.t_s, abs=1e-6)
        for tag, (name, *_rest) in __import__(
            "demtrack.core.video.klv", fromlist=["_MAP"]
        )._MAP.items():
            assert getattr(back, name) == pytest.approx(getattr(d, name), abs=STEP[tag] / 2 + 1e-9)


def test_signed_out_of_range_marker_reads_as_none():
    assert _decode_value(6, bytes.fromhex("8000")) is None
    assert _decode_value(19, bytes.fromhex("80000000")) is None


def poses(n: int) -> list[UasDatalink]:
    return [
        UasDatalink(
            t_s=1_800_000_000.0 + k * 0.04,
            platform_heading_deg=90.0 + k,
            platform_pitch_deg=2.0,
            platform_roll_deg=-1.5,
            sensor_lat_deg=47.0 + k * 1e-5,
            sensor_lon_deg=8.0,
            sensor_alt_msl_m=620.0,
            sensor_hfov_deg=30.0 - 0.1 * k,
            sensor_vfov_deg=17.0,
            sensor_rel_az_deg=10.0 + 0.5 * k,
            sensor_rel_el_deg=-20.0 + 0.25 * k,
            sensor_rel_roll_deg=0.0,
        )
        for k in range(n)
    ]


def test_klv_in_an_mpeg_ts_comes_back_with_the_frames(tmp_path):
    path = tmp_path / "fmv.ts"
    written = poses(20)
    c = av.open(str(path), "w", format="mpegts")
    v = c.add_stream("libx264", rate=25)
    v.width, v.height, v.pix_fmt = 64, 48, "yuv420p"
    data = c.add_data_stream("klv")  # PyAV muxes a KLV data stream into MPEG-TS
    for k, d in enumerate(written):
        f = av.VideoFrame.from_ndarray(np.full((48, 64, 3), 8 * k, np.uint8), format="rgb24")
        f.pts, f.time_base = k, Fraction(1, 25)
        for p in v.encode(f):
            c.mux(p)
        pkt = av.Packet(encode_uas_datalink(d))
        pkt.stream = data
        pkt.pts = pkt.dts = k * 3600
        pkt.time_base = Fraction(1, 90000)
        c.mux(pkt)
    for p in v.encode():
        c.mux(p)
    c.close()

    r = VideoReader(path, start_utc_s=1_800_000_000.0)
    assert r.has_klv
    items = list(r.items())
    frames = [i for i in items if hasattr(i, "image")]
    packets = [i for i in items if not hasattr(i, "image")]
    assert len(frames) == 20 and len(packets) == 20
    read = [d for p in packets for d in iter_uas_datalink(p.data)]
    assert [d.t_s for d in read] == pytest.approx([d.t_s for d in written], abs=1e-6)
    for got, want in zip(read, written, strict=True):
        assert got.sensor_rel_az_deg == pytest.approx(want.sensor_rel_az_deg, abs=1e-7)
        assert got.sensor_rel_el_deg == pytest.approx(want.sensor_rel_el_deg, abs=1e-7)
        assert got.sensor_hfov_deg == pytest.approx(want.sensor_hfov_deg, abs=180 / 65535)
    # the packets' PTS are on the frames' clock: packet k with frame k
    np.testing.assert_allclose([p.t_s for p in packets], [f.t_s for f in frames], atol=1e-3)
    assert [d.t_s for p in r.klv_packets() for d in iter_uas_datalink(p.data)] == [
        d.t_s for d in read
    ]


def test_to_pose_sample_maps_angles_and_makes_msl_ellipsoidal():
    pytest.importorskip("demtrack.core.camera.pose_series")
    from demtrack.core.geo.geodesy import LocalFrame
    from demtrack.core.geo.geoid import GeoidModel
    from demtrack.core.video.klv import to_pose_sample

    frame = LocalFrame(47.0, 8.0, 600.0)
    geoid = GeoidModel.constant(48.5)
    d = poses(1)[0]
    back = parse_uas_datalink(encode_uas_datalink(d))
    p = to_pose_sample(back, frame, geoid)
    assert p.t_s == pytest.approx(d.t_s, abs=1e-6)
    assert p.pan_deg == pytest.approx(10.0, abs=1e-7)
    assert p.tilt_deg == pytest.approx(-20.0, abs=1e-7)
    assert p.hfov_deg == pytest.approx(30.0, abs=0.003)
    assert p.platform_ypr_deg == pytest.approx((90.0, 2.0, -1.5), abs=0.002)
    # MSL 620 m + N 48.5 m = 668.5 m ellipsoidal, 68.5 m above the 600 m anchor
    assert p.position_enu[2] == pytest.approx(68.5, abs=0.31)
    assert abs(p.position_enu[0]) < 0.01 and abs(p.position_enu[1]) < 0.01
