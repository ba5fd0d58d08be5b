"""``PUT /api/sensors/{id}/frame`` and ``GET .../frame.jpg``: the newest frame per camera.

Oracles: the frame served is byte for byte the frame posted, and decodes (OpenCV) to the
colour it was made of; the JPEG check's sizes agree with OpenCV's decode; an unchanged
poll is a 304 with no body until a new frame changes the tag.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from server_helpers import AUTH

from demtrack.core.errors import VideoError
from demtrack.core.io.times import parse_iso_time
from demtrack.server.video.frame_book import FrameBook
from demtrack.server.video.jpeg import encode_jpeg, jpeg_size

T0 = parse_iso_time("2026-12-01T14:30:00Z", "t")


def solid_jpeg(rgb: tuple[int, int, int], w: int = 320, h: int = 180, quality: int = 90) -> bytes:
    return encode_jpeg(np.full((h, w, 3), rgb, np.uint8), quality=quality)


def put(client, sensor: str, body: bytes, t, **headers):
    h = {**AUTH, "Content-Type": "image/jpeg", **headers}
    if t is not None:
        h["X-Frame-Time"] = str(t)
    return client.put(f"/api/sensors/{sensor}/frame", content=body, headers=h)


def test_frame_round_trip_etag_and_no_store(client):
    assert client.get("/api/sensors/cam1/frame.jpg", headers=AUTH).status_code == 404
    red = solid_jpeg((220, 20, 20))
    ack = put(client, "cam1", red, "2026-12-01T14:30:00.250Z")
    assert ack.status_code == 200, ack.text
    body = ack.json()
    assert body["stored"] and (body["width"], body["height"]) == (320, 180)
    assert body["t_s"] == pytest.approx(T0 + 0.25)
    got = client.get("/api/sensors/cam1/frame.jpg", headers=AUTH)
    assert got.status_code == 200 and got.content == red
    assert got.headers["content-type"] == "image/jpeg"
    assert got.headers["cache-control"] == "no-store"
    assert got.headers["x-frame-time"] == "2026-12-01T14:30:00.250Z"
    assert float(got.headers["x-frame-time-s"]) == pytest.approx(T0 + 0.25)
    rgb = cv2.imdecode(np.frombuffer(got.content, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]
    assert np.abs(rgb.reshape(-1, 3).mean(axis=0) - (220, 20, 20)).max() < 4
    tag = got.headers["etag"]
    # Unchanged: 304, no body, same tag; the other camera has none.
    same = client.get("/api/sensors/cam1/frame.jpg", headers={**AUTH, "If-None-Match": tag})
    assert same.status_code == 304 and same.content == b"" and same.headers["etag"] == tag
    assert client.get("/api/sensors/cam2/frame.jpg", headers=AUTH).status_code == 404
    # A newer frame (UNIX seconds this time) changes the tag and the bytes.
    blue = solid_jpeg((20, 20, 220))
    assert put(client, "cam1", blue, T0 + 1.0).json()["stored"]
    new = client.get("/api/sensors/cam1/frame.jpg", headers={**AUTH, "If-None-Match": tag})
    assert new.status_code == 200 and new.content == blue and new.headers["etag"] != tag
    # An older frame is not stored: the newest stays.
    late = put(client, "cam1", red, T0 + 0.5).json()
    assert late["stored"] is False and "older" in late["reason"]
    assert client.get("/api/sensors/cam1/frame.jpg", headers=AUTH).content == blue


def test_frame_boxes_travel_with_the_frame(client):
    jpeg = solid_jpeg((10, 200, 10))
    boxes = "[[10, 20, 30.5, 60], [100, 40, 140, 90]]"
    assert put(client, "cam2", jpeg, T0, **{"X-Frame-Boxes": boxes}).json()["stored"]
    got = client.get("/api/sensors/cam2/frame.jpg", headers=AUTH)
    assert got.headers["x-frame-boxes"] == "[[10.0, 20.0, 30.5, 60.0], [100.0, 40.0, 140.0, 90.0]]"
    bad = put(client, "cam2", jpeg, T0 + 1, **{"X-Frame-Boxes": "[[3, 4, 1, 2]]"})
    assert bad.status_code == 422 and "u_max >= u_min" in bad.json()["detail"]


@pytest.mark.parametrize(
    ("body", "headers", "status", "words"),
    [
        (b"not a jpeg at all", {}, 422, "not a JPEG"),
        ("TRUNCATED", {}, 422, "truncated JPEG"),
        ("JPEG", {"Content-Type": "image/png"}, 422, "image/jpeg"),
        ("JPEG", {"X-Frame-Time": "2026-12-01T14:30:00"}, 422, "X-Frame-Time"),
        ("JPEG", {"X-Frame-Time": ""}, 422, "X-Frame-Time header required"),
        ("JPEG", {"X-Frame-Boxes": "[1, 2"}, 422, "X-Frame-Boxes is not JSON"),
    ],
)
def test_bad_frames_are_refused_in_one_line(client, body, headers, status, words):
    jpeg = solid_jpeg((128, 128, 128))
    body = jpeg if body == "JPEG" else jpeg[: len(jpeg) // 2] if body == "TRUNCATED" else body
    h = {"X-Frame-Time": str(T0), **headers}
    r = put(client, "cam1", body, None, **h)
    assert r.status_code == status, r.text
    detail = r.json()["detail"]
    assert words in detail and "\n" not in detail
    assert client.get("/api/sensors/cam1/frame.jpg", headers=AUTH).status_code == 404


def test_frame_needs_the_token_and_a_known_sensor(client_factory):
    c = client_factory(max_frame_bytes=4000)
    jpeg = solid_jpeg((1, 2, 3))
    assert c.put("/api/sensors/cam1/frame", content=jpeg).status_code == 401
    assert put(c, "nope", jpeg, T0).status_code == 404
    assert c.get("/api/sensors/cam1/frame.jpg").status_code == 401
    assert c.get("/api/sensors/nope/frame.jpg", headers=AUTH).status_code == 404
    noisy = encode_jpeg(np.random.default_rng(0).integers(0, 255, (180, 320, 3), np.uint8))
    big = put(c, "cam1", noisy, T0)
    assert big.status_code == 422 and "limit is 4000" in big.json()["detail"]


def test_open_reads_serve_frames_without_the_token(client_factory):
    c = client_factory(open_reads=True)
    assert put(c, "cam3", solid_jpeg((5, 5, 5)), T0).status_code == 200
    assert c.get("/api/sensors/cam3/frame.jpg").status_code == 200


@pytest.mark.parametrize(("w", "h"), [(1, 1), (17, 9), (1280, 720), (640, 481)])
@pytest.mark.parametrize("progressive", [False, True])
def test_jpeg_size_agrees_with_opencv(w, h, progressive):
    img = np.random.default_rng(w * h).integers(0, 255, (h, w, 3), np.uint8)
    flags = [cv2.IMWRITE_JPEG_QUALITY, 80, cv2.IMWRITE_JPEG_PROGRESSIVE, int(progressive)]
    ok, buf = cv2.imencode(".jpg", img, flags)
    data = buf.tobytes()
    dec = cv2.imdecode(buf, cv2.IMREAD_COLOR)
    assert jpeg_size(data) == (dec.shape[1], dec.shape[0]) == (w, h)
    assert jpeg_size(data + b"\0\0") == (w, h)  # padded after the end marker
    for cut in (len(data) - 1, len(data) // 3, 3):
        with pytest.raises(VideoError):
            jpeg_size(data[:cut])


def test_encode_jpeg_downscales_to_the_width_limit():
    img = np.zeros((1080, 1920, 3), np.uint8)
    img[:, :960] = (255, 0, 0)
    data = encode_jpeg(img, max_width=1280)
    assert jpeg_size(data) == (1280, 720)
    dec = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)[:, :, ::-1]
    assert tuple(dec[360, 200]) == pytest.approx((255, 0, 0), abs=3)  # RGB kept, not BGR
    assert tuple(dec[360, 1100]) == pytest.approx((0, 0, 0), abs=3)
    grey = encode_jpeg(np.full((100, 200), 77, np.uint8))
    assert jpeg_size(grey) == (200, 100)


def test_book_keeps_one_frame_per_sensor_and_unique_tags():
    book = FrameBook(["a", "b"], clock=lambda: 5.0)
    jpeg = solid_jpeg((9, 9, 9), 16, 16)
    tags = {book.put(s, jpeg, t).etag for s in "ab" for t in (1.0, 2.0, 3.0)}  # type: ignore[union-attr]
    assert len(tags) == 6
    assert book.get("a").t_s == 3.0 and book.get("b").received_s == 5.0  # type: ignore[union-attr]
    other = FrameBook(["a"])
    assert other.put("a", jpeg, 1.0).etag not in tags  # type: ignore[union-attr]
    with pytest.raises(KeyError):
        book.put("c", jpeg, 1.0)
    with pytest.raises(VideoError, match="finite"):
        book.put("a", jpeg, float("nan"))


def test_frame_index_lists_tags_and_answers_304_until_a_frame_changes(client):
    empty = client.get("/api/frames", headers=AUTH)
    assert empty.status_code == 200 and empty.json() == {"frames": {}}
    tag0 = empty.headers["etag"]
    put(client, "cam2", solid_jpeg((1, 1, 1)), T0 + 2)
    idx = client.get("/api/frames", headers={**AUTH, "If-None-Match": tag0})
    assert idx.status_code == 200 and idx.headers["cache-control"] == "no-store"
    (entry,) = idx.json()["frames"].values()
    frame = client.get("/api/sensors/cam2/frame.jpg", headers=AUTH)
    assert entry["etag"] == frame.headers["etag"]
    assert entry["time_utc"] == "2026-12-01T14:30:02.000Z" and entry["width"] == 320
    tag1 = idx.headers["etag"]
    assert tag1 != tag0
    same = client.get("/api/frames", headers={**AUTH, "If-None-Match": tag1})
    assert same.status_code == 304 and same.content == b""
    put(client, "cam1", solid_jpeg((2, 2, 2)), T0 + 3)
    new = client.get("/api/frames", headers={**AUTH, "If-None-Match": tag1})
    assert new.status_code == 200 and sorted(new.json()["frames"]) == ["cam1", "cam2"]
    assert client.get("/api/frames").status_code == 401
