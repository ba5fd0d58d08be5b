"""``demtrack watch`` on a live stream that stalls: it reconnects with back-off, then gives
up in one line; an unreachable stream is one line at once."""

from __future__ import annotations

import socket
import sys
import threading
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parents[1] / "core" / "video"))
from synth import write_video  # noqa: E402

from demtrack.cli import main  # noqa: E402

pytestmark = pytest.mark.timeout(300)


def stalling_server(data: bytes):
    """A TCP server: each connection gets the whole stream, then silence (never closed)."""
    server = socket.socket()
    server.bind(("127.0.0.1", 0))
    server.listen(8)
    server.settimeout(0.2)
    stop = threading.Event()
    accepted = []

    def serve():
        while not stop.is_set():
            try:
                conn, _ = server.accept()
            except OSError:
                continue
            conn.sendall(data)
            accepted.append(conn)
        for c in accepted:
            c.close()
        server.close()

    th = threading.Thread(target=serve, daemon=True)
    th.start()
    return server.getsockname()[1], accepted, stop, th


def test_a_stalling_stream_is_reopened_then_given_up(sample_site_dir, tmp_path, capsys):
    clip = write_video(tmp_path / "live.ts", [], size=(1280, 720), n_frames=12, creation_time=None)
    port, accepted, stop, th = stalling_server(clip.path.read_bytes())
    out = tmp_path / "live.jsonl"
    try:
        rc = main(
            [
                "watch", "--site", str(sample_site_dir), "--sensor", "cam1",
                "--source", f"tcp://127.0.0.1:{port}", "--timeout", "1", "--reconnects", "1",
                "-o", str(out), "--quiet",
            ]
        )  # fmt: skip
    finally:
        stop.set()
        th.join(5)
    err = capsys.readouterr().err
    assert rc == 2
    assert len(accepted) == 2  # the first session and one reconnect
    assert "reconnecting in 1 s" in err
    last = err.strip().splitlines()[-1]
    assert "stalled" in last and "gave up after 1 reconnects" in last
    assert out.exists()  # what was found before the stall is kept (here: an empty scene)


def test_an_unreachable_stream_is_one_line(sample_site_dir, tmp_path, capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    rc = main(
        [
            "watch", "--site", str(sample_site_dir), "--sensor", "cam1",
            "--source", f"tcp://127.0.0.1:{port}", "--timeout", "1",
            "-o", str(tmp_path / "x.jsonl"), "--quiet",
        ]
    )  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "unreachable" in err and "\n" not in err
