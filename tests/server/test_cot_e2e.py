"""CoT from a real ``demtrack serve --cot``: a multicast receiver and a TCP server on
loopback get the tracks and markers; uid, type, position (against pyproj), time, stale,
CE and LE (against the fixes' covariances) are checked, and the TCP stream reconnects."""

from __future__ import annotations

import json
import re
import socket
import subprocess
import time
from pathlib import Path

import httpx2 as httpx
import numpy as np
import pytest
from pyproj import Transformer
from server_helpers import AUTH, start_server, walk

from demtrack.core.io.cot import circular_error_m, event_from_xml
from demtrack.core.site.folder import load_site

pytestmark = pytest.mark.timeout(180)
T0 = 1_780_000_000.0  # 2026-05-28T20:26:40Z
GROUP = "239.2.3.1"


def start(site: Path, db: Path, cot: str) -> tuple[subprocess.Popen, str]:
    return start_server(site, db, "--cot", cot, timeout_s=60)


def feed(c: httpx.Client, t0: float, n: int = 30, key: str = "a") -> None:
    recs = []
    for k in range(n):
        recs += walk(t0=t0, n=n)[k : k + 1]
        recs += walk(sensor="cam2", t0=t0, n=n, u0=300, v=600, cls="human")[k : k + 1]
    for i in range(0, len(recs), 6):
        r = c.post(
            "/api/detections", json={"detections": recs[i : i + 6], "batch_key": f"{key}{i}"}
        )
        assert r.status_code == 200, r.text


def stream_messages(url: str) -> list[dict]:
    """Every stored stream message, read from the server's own /ws (fix covariances)."""
    from websockets.sync.client import connect

    out: list[dict] = []
    with connect(url.replace("http://", "ws://") + "/ws?since=0", additional_headers=AUTH) as ws:
        hello = json.loads(ws.recv(timeout=10))
        while not out or out[-1]["seq"] < hello["last_seq"]:
            out.append(json.loads(ws.recv(timeout=10)))
    return out


def to_geodetic_pyproj(anchor: dict):
    """ENU -> WGS84 through PROJ's own topocentric conversion (not demtrack's frame)."""
    pipe = (
        "+proj=pipeline +step +inv +proj=topocentric +ellps=WGS84"
        f" +lat_0={anchor['lat_deg']} +lon_0={anchor['lon_deg']} +h_0={anchor['h_m']}"
        " +step +inv +proj=cart +ellps=WGS84"
    )
    t = Transformer.from_pipeline(pipe)
    return lambda e, n, u: t.transform(e, n, u)  # lon, lat, h


def check_track_events(events, url, site_dir, c):
    """Each track's newest event against the track, its fixes and the DEM."""
    msgs = stream_messages(url)
    fixes = {m["fix"]["detection_id"]: m["fix"] for m in msgs if m["type"] == "fix"}
    tracks = {t["id"]: t for t in c.get("/api/tracks").json()["tracks"]}
    geo = to_geodetic_pyproj(c.get("/api/site").json()["frame"])
    dem = load_site(site_dir).dem
    newest = {}
    for ev in events:
        if ".track." in ev.uid:
            newest[ev.uid] = ev
    assert len(newest) >= 2, "a vehicle track and a person track"
    types = set()
    for uid, ev in newest.items():
        tid = int(uid.rsplit(".", 1)[1])
        track = tracks[tid]
        types.add((track["cls"], ev.type))
        p = next(p for p in track["points"] if abs(p["t_s"] - ev.time_s) < 5e-4)
        lon, lat, h = geo(p["e_m"], p["n_m"], p["u_m"])
        assert ev.lat_deg == pytest.approx(lat, abs=1e-7) and ev.lon_deg == pytest.approx(
            lon, abs=1e-7
        )
        assert ev.hae_m == pytest.approx(h, abs=0.006)  # hae: above the ellipsoid
        assert ev.start_s == ev.time_s and ev.stale_s - ev.time_s == pytest.approx(60.0, abs=2e-3)
        assert ev.how == "m-f" and ev.callsign == f"{track['cls']} {tid}"
        assert "MGRS " in ev.remarks
        # CE/LE from the covariance of the fix hits behind the point (nearest hit each)
        covs = []
        for d in p["detection_ids"]:
            hits = fixes[d]["hits"]
            best = min(hits, key=lambda x: (x["e_m"] - p["e_m"]) ** 2 + (x["n_m"] - p["n_m"]) ** 2)
            covs.append(np.array(best["cov_en_m2"]))
        cov = covs[0] if len(covs) == 1 else np.linalg.inv(sum(np.linalg.inv(x) for x in covs))
        lam = np.linalg.eigvalsh(cov)
        assert np.sqrt(lam[0]) - 0.005 <= ev.ce_m <= np.sqrt(lam[1]) + 0.005
        assert ev.ce_m == pytest.approx(circular_error_m(cov), abs=0.006)
        g = np.array([v[0] for v in dem.gradient(np.array([p["e_m"]]), np.array([p["n_m"]]))])
        var = float(dem.sample_variance(np.array([p["e_m"]]), np.array([p["n_m"]]))[0])
        assert ev.le_m == pytest.approx(np.sqrt(g @ cov @ g + var), abs=0.006)
        assert ev.course_deg is not None and 0 <= ev.course_deg < 360
    assert ("vehicle", "a-u-G-E-V") in types and ("human", "a-u-G-U-C-I") in types


def recv_until(sock: socket.socket, events: list, want, deadline_s: float = 60) -> None:
    deadline = time.monotonic() + deadline_s
    while not want(events):
        assert time.monotonic() < deadline, f"only {len(events)} CoT events arrived"
        try:
            data = sock.recv(65536)
        except TimeoutError:
            continue
        assert data.startswith(b'<?xml version="1.0" encoding="UTF-8"?><event ')
        events.append(event_from_xml(data))


def drain(sock: socket.socket, events: list, quiet_s: float = 1.5) -> None:
    """Receive until nothing has come for ``quiet_s``."""
    sock.settimeout(quiet_s)
    while True:
        try:
            events.append(event_from_xml(sock.recv(65536)))
        except TimeoutError:
            sock.settimeout(0.5)
            return


def test_multicast_udp_gets_tracks_and_markers(sample_site_dir, tmp_path):
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM, socket.IPPROTO_UDP)
    rx.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    rx.bind(("", 0))
    port = rx.getsockname()[1]
    rx.setsockopt(
        socket.IPPROTO_IP,
        socket.IP_ADD_MEMBERSHIP,
        socket.inet_aton(GROUP) + socket.inet_aton("127.0.0.1"),
    )
    rx.settimeout(0.5)
    proc, url = start(
        sample_site_dir, tmp_path / "c.sqlite3", f"udp://{GROUP}:{port}?ttl=1&iface=127.0.0.1"
    )
    events: list = []
    try:
        with httpx.Client(base_url=url, headers=AUTH, timeout=30) as c:
            feed(c, T0)
            m = c.post("/api/markers", json={"t_s": T0, "name": "OP1", "e_m": 120.0, "n_m": -35.5})
            assert m.status_code == 201, m.text
            marker = m.json()
            recv_until(rx, events, lambda evs: any(".marker." in e.uid for e in evs))
            drain(rx, events)  # the last track updates
            check_track_events(events, url, sample_site_dir, c)
            ev = next(e for e in events if e.uid.endswith(f".marker.{marker['id']}"))
            assert ev.type == "b-m-p-s-m" and ev.how == "h-e" and ev.callsign == "OP1"
            assert (ev.lat_deg, ev.lon_deg) == pytest.approx(
                (marker["lat_deg"], marker["lon_deg"]), abs=1e-7
            )
            assert ev.hae_m == pytest.approx(marker["h_m"], abs=0.006)
            assert f"MGRS {marker['mgrs']}" in ev.remarks and marker["time_utc"] in ev.remarks
            assert ev.stale_s - ev.time_s == pytest.approx(86_400.0)
            assert abs(ev.time_s - time.time()) < 120  # stamped when sent
            assert c.delete(f"/api/markers/{marker['id']}").status_code in (200, 204)
            recv_until(rx, events, lambda evs: any(e.type == "t-x-d-d" for e in evs))
            gone = next(e for e in events if e.type == "t-x-d-d")
            assert gone.link_uid == ev.uid
    finally:
        proc.kill()
        proc.wait(10)
        rx.close()


def test_tcp_stream_is_bare_events_and_reconnects(sample_site_dir, tmp_path):
    srv = socket.create_server(("127.0.0.1", 0))
    srv.settimeout(60)
    port = srv.getsockname()[1]
    proc, url = start(sample_site_dir, tmp_path / "c.sqlite3", f"tcp://127.0.0.1:{port}")

    def read_events(conn: socket.socket, want: int) -> tuple[bytes, list]:
        conn.settimeout(0.5)
        buf = b""
        deadline = time.monotonic() + 60
        while buf.count(b"</event>") < want:
            assert time.monotonic() < deadline, f"{buf.count(b'</event>')} events by TCP"
            try:
                chunk = conn.recv(65536)
            except TimeoutError:
                continue
            if not chunk:
                break
            buf += chunk
        parts = re.findall(rb"<event .*?</event>", buf)
        return buf, [event_from_xml(p) for p in parts]

    try:
        with httpx.Client(base_url=url, headers=AUTH, timeout=30) as c:
            feed(c, T0)
            conn, _ = srv.accept()
            buf, events = read_events(conn, 4)
            # TAK Server's streaming form: events back to back, no declaration, no newline
            assert buf.startswith(b"<event ") and b"<?xml" not in buf and b"\n" not in buf
            assert (
                b"".join(re.findall(rb"<event .*?</event>", buf))
                == buf[: buf.rfind(b"</event>") + 8]
            )
            assert {e.type for e in events} >= {"a-u-G-E-V"}
            conn.close()  # the TAK server drops the connection
            # the sender notices on a later send, backs off and reconnects
            k = 1
            conn2 = None
            srv.settimeout(1.0)
            while conn2 is None:
                assert k < 30, "the CoT sender did not reconnect"
                feed(c, T0 + 10 * k, n=5, key=f"r{k}")
                try:
                    conn2, _ = srv.accept()
                except TimeoutError:
                    k += 1
            feed(c, T0 + 10 * (k + 1), n=5, key="after")
            _, again = read_events(conn2, 1)
            assert again and all(e.time_s >= T0 + 10 for e in again if ".track." in e.uid)
            conn2.close()
    finally:
        proc.kill()
        proc.wait(10)
        srv.close()
