"""``sensor_pose`` messages: the rate limit, the message on ``/ws``, the 3D frustum."""

from __future__ import annotations

import time

import numpy as np
import pytest
from pydantic import TypeAdapter
from server_helpers import AUTH

from demtrack.core.camera.pose_series import PoseSample, camera_at
from demtrack.core.site.folder import load_site
from demtrack.server.ingest.pose_stream import PoseAnnouncer
from demtrack.server.messages import SensorPoseMessage, StreamMessage, messages_schema
from demtrack.server.store.codec import payload_dict

pytestmark = pytest.mark.timeout(300)

T0 = 1_780_000_000.0


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


def test_the_rate_limit_sends_at_most_one_per_interval_and_always_the_newest():
    clock = Clock()
    a = PoseAnnouncer(0.125, clock=clock)  # binary fractions: exact sums
    newest = {"cam1": PoseSample(T0, 1.0, 0.0)}
    assert [p.pan_deg for _, p in a.due(["cam1"], newest)] == [1.0]
    assert a.due(["cam1"], newest) == []  # the same pose again: nothing new
    for k in range(2, 6):  # four poses within the interval: held back
        clock.t += 1 / 64
        newest["cam1"] = PoseSample(T0 + k, float(k), 0.0)
        assert a.due(["cam1"], newest) == []
    assert a.next_flush_s() == 0.0625
    assert a.flush(newest) == []  # the interval has not passed yet
    clock.t += 0.0625
    (msg,) = a.flush(newest)
    assert msg[0] == "sensor_pose" and msg[1].pan_deg == 5.0  # the newest, once
    assert a.next_flush_s() is None and a.n_sent == 2
    # another sensor has its own interval
    newest["cam2"] = PoseSample(T0, 7.0, 0.0)
    assert [p.sensor for _, p in a.due(["cam2"], newest)] == ["cam2"]


def test_the_payload_is_the_documented_message():
    a = PoseAnnouncer(0.0)
    a.describe = lambda s, p: {"enu": [[0.0, 1.0, 2.0]], "complete": True}
    ((_, payload),) = a.due(["cam1"], {"cam1": PoseSample(T0, 1.5, -2.0, hfov_deg=30.0)})
    msg = {**payload_dict(payload), "seq": 9}
    parsed = TypeAdapter(StreamMessage).validate_python(msg)
    assert isinstance(parsed, SensorPoseMessage) and parsed.hfov_deg == 30.0
    assert "sensor_pose" in messages_schema()["x-server-types"]


def _recv_type(ws, kind: str, n: int = 50) -> dict:
    for _ in range(n):
        m = ws.receive_json()
        if m["type"] == kind:
            return m
    raise AssertionError(f"no {kind} message")


def test_a_posted_pose_is_streamed_with_the_footprint_the_api_serves(client):
    with client.websocket_connect(f"/ws?token={AUTH['Authorization'][7:]}") as ws:
        assert ws.receive_json()["type"] == "hello"
        r = client.post(
            "/api/sensors/cam2/poses",
            headers=AUTH,
            json={"poses": [{"t": T0, "pan_deg": -40.0, "tilt_deg": -20.0, "hfov_deg": 70.0}]},
        )
        assert r.status_code == 200
        msg = _recv_type(ws, "sensor_pose")
    SensorPoseMessage.model_validate(msg)
    assert (msg["sensor"], msg["t_s"], msg["pan_deg"], msg["hfov_deg"]) == (
        "cam2",
        T0,
        -40.0,
        70.0,
    )
    listed = client.get("/api/sensors/cam2", headers=AUTH).json()
    assert msg["footprint"] == listed["footprint"]
    # stored with a seq: a client that resumes gets it again
    again = client.app.state.console.store.events_since(msg["seq"] - 1, 1)
    assert again[0]["type"] == "sensor_pose" and again[0]["pan_deg"] == -40.0


def test_a_held_back_pose_goes_out_when_its_interval_ends(client_factory):
    c = client_factory(pose_message_interval_s=2.0)  # wide: slow machines
    store = c.app.state.console.store

    def poses_sent():
        return [e["pan_deg"] for e in store.events_since(0, 1000) if e["type"] == "sensor_pose"]

    for k in range(3):
        body = {"poses": [{"t": T0 + k, "pan_deg": float(k), "tilt_deg": -10.0}]}
        assert c.post("/api/sensors/cam1/poses", headers=AUTH, json=body).status_code == 200
    assert poses_sent() == [0.0]  # within the interval: the other two wait
    deadline = time.monotonic() + 20
    while poses_sent() == [0.0] and time.monotonic() < deadline:
        time.sleep(0.05)
    assert poses_sent() == [0.0, 2.0]  # the newest, not the one in between


def test_the_3d_frustum_turns_to_the_pose(sample_site_dir):
    from demtrack.server.scene3d import Scene3D
    from demtrack.server.scene3d.frusta import wxyz_from_matrix

    site = load_site(sample_site_dir)
    sc = Scene3D(site, host="127.0.0.1", port=0, max_rays=5, require_session=False)
    try:
        assert sc.wait_ready(120) and sc.error is None
        handle = sc.nodes["/cameras/cam1"]
        before = np.array(handle.wxyz)
        head = site.sensors["cam1"].head
        msgs = [
            {"type": "sensor_pose", "seq": k, "sensor": "cam1", "t_s": T0 + k, "pan_deg": pan,
             "tilt_deg": -12.0, "roll_deg": 0.0, "hfov_deg": 50.0, "footprint": None}
            for k, pan in enumerate((10.0, 20.0, 30.0))
        ]  # fmt: skip
        sc.publish(msgs)
        assert sc.flush(30)
        want = camera_at(head, PoseSample(T0, 30.0, -12.0, hfov_deg=50.0))
        np.testing.assert_allclose(handle.wxyz, wxyz_from_matrix(want.R_world_cam), atol=1e-12)
        assert not np.allclose(handle.wxyz, before)
        assert sc.poses.n_moves == 1  # three poses between two renders: one move
        assert handle.image is None
    finally:
        sc.stop()
