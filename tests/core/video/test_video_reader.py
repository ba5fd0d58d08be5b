"""VideoReader: frame times from PTS in UTC, start time from metadata or the caller, and
one-line errors for missing, corrupt and truncated files, unreachable and stalled streams."""

from __future__ import annotations

import socket
import threading
import time

import numpy as np
import pytest
from synth import START, Mover, write_video

from demtrack.core.errors import VideoError, VideoStallError
from demtrack.core.video.reader import VideoReader, is_live_source


@pytest.fixture(scope="module")
def clip(tmp_path_factory):
    path = tmp_path_factory.mktemp("reader") / "clip.mp4"
    return write_video(path, [Mover("human", (10, 50), (2.0, 0.0), (10, 30))], n_frames=30)


def test_frame_times_come_from_pts_and_creation_time(clip):
    r = VideoReader(clip.path)
    assert r.size == (320, 240)
    assert r.fps == 25.0
    assert r.start_utc_s == START
    frames = list(r)
    assert [f.index for f in frames] == list(range(30))
    np.testing.assert_allclose([f.t_s for f in frames], START + np.arange(30) / 25.0, atol=1e-6)
    assert frames[0].image.shape == (240, 320, 3) and frames[0].image.dtype == np.uint8


def test_start_given_wins_and_gray_frames(clip):
    r = VideoReader(clip.path, start_utc_s=1_800_000_000.0, gray=True)
    frames = list(r)
    assert frames[0].t_s == 1_800_000_000.0
    assert frames[5].t_s == pytest.approx(1_800_000_000.2, abs=1e-6)
    assert frames[0].image.shape == (240, 320)


def test_a_file_without_start_time_names_the_fix(tmp_path):
    clip = write_video(tmp_path / "bare.mp4", [], n_frames=3, creation_time=None)
    with pytest.raises(VideoError, match="--start"):
        VideoReader(clip.path)
    assert len(list(VideoReader(clip.path, start_utc_s=START))) == 3


def test_missing_and_corrupt_files_are_one_line_errors(tmp_path, clip):
    with pytest.raises(VideoError, match="not found"):
        VideoReader(tmp_path / "none.mp4")
    junk = tmp_path / "junk.mp4"
    junk.write_bytes(np.random.default_rng(0).integers(0, 256, 5000, dtype=np.uint8).tobytes())
    with pytest.raises(VideoError) as err:
        VideoReader(junk, start_utc_s=START)
    assert "\n" not in str(err.value)
    # an MP4 cut in half has lost its index (the moov box is written last)
    cut = tmp_path / "cut.mp4"
    data = clip.path.read_bytes()
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(VideoError) as err:
        list(VideoReader(cut, start_utc_s=START))
    assert "\n" not in str(err.value)


def test_truncated_transport_stream_gives_what_it_has(tmp_path):
    clip = write_video(tmp_path / "c.ts", [], n_frames=50, creation_time=None)
    data = clip.path.read_bytes()
    cut = tmp_path / "cut.ts"
    cut.write_bytes(data[: len(data) // 2])
    frames = list(VideoReader(cut, start_utc_s=START))
    assert 5 < len(frames) < 50  # the frames before the cut, timed as in the whole file
    np.testing.assert_allclose(
        [f.t_s for f in frames], START + np.arange(len(frames)) / 25.0, atol=1e-3
    )


def test_live_sources_are_told_apart():
    assert is_live_source("rtsp://cam/stream") and is_live_source("udp://0.0.0.0:5000")
    assert not is_live_source("/data/clip.mp4") and not is_live_source("clip.mp4")


def test_an_unreachable_stream_is_a_one_line_error():
    with socket.socket() as s:  # a port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    t0 = time.monotonic()
    with pytest.raises(VideoError, match="unreachable") as err:
        VideoReader(f"tcp://127.0.0.1:{port}", timeout_s=1.0)
    assert "\n" not in str(err.value)
    assert time.monotonic() - t0 < 30


def test_a_stream_that_stalls_raises_a_stall_error(tmp_path):
    clip = write_video(tmp_path / "s.ts", [], n_frames=40, creation_time=None)
    data = clip.path.read_bytes()
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(4)
    port = server.getsockname()[1]
    stop = threading.Event()

    def serve():  # each connection: the whole stream, then silence (a stall), never closed
        conns = []
        server.settimeout(0.2)
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                continue
            conn.sendall(data)
            conns.append(conn)
        for c in conns:
            c.close()

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    try:
        r = VideoReader(f"tcp://127.0.0.1:{port}", timeout_s=1.0, latency_s=0.5)
        got = []
        before = time.time()
        with pytest.raises(VideoStallError, match="stalled"):
            for f in r:
                got.append(f)
        assert len(got) >= 30
        # live time: the wall clock at the first packet minus the latency, plus PTS offsets
        assert before - 0.5 - 1.0 < got[0].t_s < time.time()
        np.testing.assert_allclose(np.diff([f.t_s for f in got]), 0.04, atol=1e-6)
    finally:
        stop.set()
        th.join(5)
        server.close()
