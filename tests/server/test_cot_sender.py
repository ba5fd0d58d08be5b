"""The CoT sender's parts: URLs, the multicast TTL, dropping instead of waiting, coalescing,
and the one-line start-up error for a bad URL."""

from __future__ import annotations

import socket
import subprocess
import sys

import numpy as np
import pytest
from server_helpers import make_app

from demtrack.core.errors import SettingsError
from demtrack.core.io.cot import COT_UNKNOWN_M, event_from_xml
from demtrack.core.site.folder import load_site
from demtrack.server.cot.events import CotBuilder, fused_covariance
from demtrack.server.cot.sender import CotSender
from demtrack.server.cot.target import parse_cot_url
from demtrack.server.cot.transport import TcpTransport, UdpTransport

T0 = 1_780_000_000.0


@pytest.mark.parametrize(
    ("url", "want"),
    [
        ("udp://239.2.3.1:6969", ("udp", "239.2.3.1", 6969, 1, None, True)),
        (
            "udp://239.2.3.1:6969?ttl=8&iface=127.0.0.1",
            ("udp", "239.2.3.1", 6969, 8, "127.0.0.1", True),
        ),
        ("udp://10.0.0.5:4242", ("udp", "10.0.0.5", 4242, 1, None, False)),
        ("tcp://takserver:8087", ("tcp", "takserver", 8087, 1, None, False)),
    ],
)
def test_urls(url, want):
    t = parse_cot_url(url)
    assert (t.scheme, t.host, t.port, t.ttl, t.iface, t.multicast) == want


@pytest.mark.parametrize(
    ("url", "says"),
    [
        ("http://h:1", "scheme"),
        ("udp://h", "port"),
        ("udp://h:0", "port"),
        ("udp://h:70000", "range"),
        ("udp://:5", "host"),
        ("tcp://h:1?ttl=2", "ttl"),
        ("udp://h:1?ttl=256", "ttl"),
        ("udp://h:1?loop=1", "loop"),
        ("udp://h:1?iface=eth0", "iface"),
        ("udp://h:1/path", "HOST:PORT"),
    ],
)
def test_bad_urls_are_one_line(url, says):
    with pytest.raises(SettingsError, match=says) as info:
        parse_cot_url(url)
    assert "\n" not in str(info.value)


def test_multicast_ttl_and_interface_are_set_on_the_socket():
    t = UdpTransport(parse_cot_url("udp://239.2.3.1:6969?ttl=5&iface=127.0.0.1"))
    try:
        assert t.sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL) == 5
        iface = t.sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, 4)
        assert socket.inet_ntoa(iface) == "127.0.0.1"
    finally:
        t.close()


def test_a_bad_setting_is_refused_by_create_app(sample_site_dir, tmp_path):
    with pytest.raises(SettingsError) as info:
        make_app(sample_site_dir, tmp_path, cot_url="udp://239.2.3.1")
    assert str(info.value).startswith("setting cot_url (DEMTRACK_COT_URL): CoT URL")
    assert "Value error" not in str(info.value)


def test_serve_with_a_bad_cot_url_exits_2_in_one_line(sample_site_dir, tmp_path):
    db = tmp_path / "x.sqlite3"
    r = subprocess.run(
        [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(sample_site_dir)]
        + ["--db", str(db), "--no-warm-up", "--port", "0", "--cot", "udp://host"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "port" in lines[0] and "Traceback" not in r.stderr
    assert not db.exists()  # nothing half-made


def _track(tid, pts, cls="vehicle", live=True):
    return {"type": "track_update", "track": {"id": tid, "cls": cls, "live": live, "points": pts}}


def _pt(t, e, n, dets=()):
    return {
        "t_s": t,
        "e_m": e,
        "n_m": n,
        "u_m": 0.0,
        "lat_deg": 40.0,
        "lon_deg": -79.0,
        "h_m": 300.0,
        "sensors": ["cam1"],
        "detection_ids": list(dets),
    }


@pytest.fixture(scope="module")
def dem(sample_site_dir):
    return load_site(sample_site_dir).dem


def test_builder_errors_course_and_speed(dem):
    b = CotBuilder("abc", dem, clock=lambda: T0)
    cov1 = [[9.0, 2.0], [2.0, 4.0]]
    far = {"e_m": 500.0, "n_m": 500.0, "sigma_m": 1.0, "cov_en_m2": [[1e4, 0], [0, 1e4]]}
    near = {"e_m": 10.0, "n_m": 20.0, "sigma_m": 3.0, "cov_en_m2": cov1}
    b.events({"type": "fix", "fix": {"detection_id": 7, "hits": [far, near]}})
    b.events({"type": "fix", "fix": {"detection_id": 8, "hits": [near | {"cov_en_m2": None}]}})
    # no fix known: CoT's unknown
    [ev] = b.events(_track(1, [_pt(T0, 10.0, 20.0, [99])]))
    assert (ev.ce_m, ev.le_m) == (COT_UNKNOWN_M, COT_UNKNOWN_M)
    # the nearest hit's covariance; two fixes are fused (the second isotropic, sigma 3)
    [ev] = b.events(_track(1, [_pt(T0 + 1, 13.0, 24.0, [7, 8])]))
    fused = fused_covariance([np.array(cov1), np.eye(2) * 9.0])
    assert b.point_covariance(_pt(0, 10, 20, [7, 8])) == pytest.approx(fused)
    assert np.linalg.eigvalsh(fused)[1] < np.linalg.eigvalsh(np.array(cov1))[1]
    assert 0 < ev.ce_m < 3.0 and 0 < ev.le_m < COT_UNKNOWN_M
    # course and speed from the previous point (3 m east, 4 m north in 1 s)
    assert ev.speed_mps == pytest.approx(5.0) and ev.course_deg == pytest.approx(36.8699, abs=1e-3)
    assert ev.stale_s == T0 + 61 and ev.uid == "demtrack.abc.track.1"
    # an ended track goes stale at its last point
    [ev] = b.events(_track(1, [_pt(T0 + 2, 13.0, 24.0)], live=False))
    assert ev.stale_s == ev.time_s == T0 + 2


def test_publish_never_waits_and_drops_when_full(dem):
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    sender = CotSender(
        CotBuilder("abc", dem),
        UdpTransport(parse_cot_url(f"udp://127.0.0.1:{rx.getsockname()[1]}")),
        queue_size=3,
    )
    # the worker is not running: the queue fills and the rest is dropped, not waited for
    for k in range(10):
        sender.publish([_track(k % 2, [_pt(T0 + k, k, 0.0)])])
    assert sender.n_dropped == 7 and sender.queue.qsize() == 3
    # started, it sends what waited, each track once: only its newest position
    sender.start()
    rx.settimeout(5)
    got = [event_from_xml(rx.recv(65536)) for _ in range(2)]
    sender.stop()
    assert sorted(e.uid for e in got) == ["demtrack.abc.track.0", "demtrack.abc.track.1"]
    assert sorted(e.time_s for e in got) == [T0 + 1, T0 + 2]
    assert sender.n_sent == 2
    rx.settimeout(0.3)
    with pytest.raises(TimeoutError):
        rx.recv(65536)
    rx.close()


def test_tcp_to_nobody_drops_and_backs_off():
    srv = socket.create_server(("127.0.0.1", 0))
    port = srv.getsockname()[1]
    srv.close()  # nothing listens there now
    t = TcpTransport(parse_cot_url(f"tcp://127.0.0.1:{port}"), backoff_s=0.5)
    assert t.send(b"<event/>") is False
    assert t.next_try > 0 and t.backoff_s == 1.0  # doubled
    assert t.send(b"<event/>") is False  # within the back-off: not even tried
    assert t.backoff_s == 1.0 and t.n_connects == 0
    t.close()
