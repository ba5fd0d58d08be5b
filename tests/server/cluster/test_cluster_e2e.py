"""Two real server processes on one PostgreSQL database: one tracker, every message, failover.

The oracle is a single process that was posted the same batches in the same order: the
cluster's tracks must equal its tracks (so no target is tracked twice, and none is lost),
whichever process received each batch and whichever process tracked it.
"""

from __future__ import annotations

import json
import os
import signal
import threading
from pathlib import Path
from typing import Any

import psycopg
import pytest
from cluster_helpers import (
    TOKEN,
    get_json,
    log_text,
    post_batch,
    scenario_batches,
    serve_on,
    stop,
    stream_rows,
    wait_tracked,
)

from demtrack.core.site.folder import load_site

pytestmark = pytest.mark.timeout(1500)

#: Scenario seconds posted (both scenarios' targets are all seen by then).
UNTIL_S = 30.0
TTL_S = 2.0


@pytest.fixture(scope="module")
def batches(sample_site_dir: Path) -> list[list[dict]]:
    return scenario_batches(load_site(sample_site_dir), UNTIL_S)


@pytest.fixture(scope="module")
def reference(sample_site_dir: Path, postgres_cluster, tmp_path_factory, batches) -> Any:
    """The tracks of one process posted every batch in order (on its own database)."""
    url = postgres_cluster.create_database()
    proc, base = serve_on(sample_site_dir, tmp_path_factory.mktemp("ref"), "ref", url)
    try:
        for batch in batches:
            post_batch(base, batch)
        wait_tracked(url)
        return get_json(base, "/api/tracks")
    finally:
        stop(proc)


def _holder(url: str) -> str:
    with psycopg.connect(url, autocommit=True) as c:
        ((owner,),) = c.execute("SELECT owner FROM site_lease WHERE expires_at > now()")
    return str(owner)


class _Listener(threading.Thread):
    """A console on ``base``'s ``/ws`` (from ``since=0``), keeping every message."""

    def __init__(self, base: str) -> None:
        super().__init__(daemon=True)
        from websockets.sync.client import connect

        self.ws = connect(base.replace("http", "ws") + f"/ws?since=0&token={TOKEN}")
        self.hello = json.loads(self.ws.recv(timeout=60))
        self.messages: list[dict[str, Any]] = []
        self.done = threading.Event()
        self.start()

    def run(self) -> None:
        try:
            while not self.done.is_set():
                self.messages.append(json.loads(self.ws.recv()))
        except Exception:  # noqa: BLE001 - closed at the end of the test
            pass

    def wait_for(self, seq: int, timeout_s: float = 120.0) -> list[dict[str, Any]]:
        import time

        deadline = time.monotonic() + timeout_s
        while (not self.messages or self.messages[-1]["seq"] < seq) and time.monotonic() < deadline:
            time.sleep(0.1)
        self.done.set()
        self.ws.close()
        return list(self.messages)


def _same_stream(got: list[dict[str, Any]], stored: list[tuple[int, str]]) -> None:
    """``got`` is the stored event log, in order, each message once, none missing."""
    assert [m["seq"] for m in got] == [s for s, _ in stored]
    assert [s for s, _ in stored] == list(range(1, len(stored) + 1))
    for m, (seq, payload) in zip(got, stored, strict=True):
        assert m == {**json.loads(payload), "seq": seq}


def test_two_processes_track_each_target_once_and_stream_everything(
    sample_site_dir: Path, tmp_path: Path, postgres_url: str, batches, reference
) -> None:
    leader, a = serve_on(sample_site_dir, tmp_path, "a", postgres_url, TTL_S)
    follower = None
    try:
        assert f":{leader.pid}:" in _holder(postgres_url)  # the first process took the lease
        follower, b = serve_on(sample_site_dir, tmp_path, "b", postgres_url, TTL_S)
        console = _Listener(b)  # a console on the follower
        for k, batch in enumerate(batches):  # batches alternate between the processes
            ack = post_batch(a if k % 2 == 0 else b, batch)
            assert ack["accepted"] == len(batch)
        n = wait_tracked(postgres_url)
        assert n == sum(len(x) for x in batches)
        assert f":{leader.pid}:" in _holder(postgres_url)
        tracks_a, tracks_b = get_json(a, "/api/tracks"), get_json(b, "/api/tracks")
        assert tracks_a == reference
        assert tracks_b == reference
        assert len(reference["tracks"]) >= 4  # several targets, each tracked once
        stored = stream_rows(postgres_url)
        _same_stream(console.wait_for(stored[-1][0]), stored)
    finally:
        stop(leader)
        if follower is not None:
            stop(follower)


def test_follower_takes_over_after_the_leader_is_killed(
    sample_site_dir: Path, tmp_path: Path, postgres_url: str, batches, reference
) -> None:
    leader, a = serve_on(sample_site_dir, tmp_path, "a", postgres_url, TTL_S)
    follower = None
    try:
        follower, b = serve_on(sample_site_dir, tmp_path, "b", postgres_url, TTL_S)
        console = _Listener(b)
        half = len(batches) // 2
        for k, batch in enumerate(batches[:half]):
            post_batch(a if k % 2 == 0 else b, batch)
        os.kill(leader.pid, signal.SIGKILL)  # mid-run: it may be tracking right now
        leader.wait(30)
        for batch in batches[half:]:  # the survivor accepts them all
            post_batch(b, batch)
        wait_tracked(postgres_url)
        assert f":{follower.pid}:" in _holder(postgres_url)
        assert get_json(b, "/api/tracks") == reference
        stored = stream_rows(postgres_url)
        _same_stream(console.wait_for(stored[-1][0]), stored)
    finally:
        stop(leader)
        if follower is not None:
            stop(follower)


def test_a_paused_leader_is_fenced_out_when_it_resumes(
    sample_site_dir: Path, tmp_path: Path, postgres_url: str, batches, reference
) -> None:
    """SIGSTOP the leader past its lease: the follower takes over; resumed, the old leader
    still believes it tracks until its first write is refused, and the tracks stay one set."""
    leader, a = serve_on(sample_site_dir, tmp_path, "a", postgres_url, TTL_S)
    follower = None
    third = len(batches) // 3
    try:
        follower, b = serve_on(sample_site_dir, tmp_path, "b", postgres_url, TTL_S)
        for k, batch in enumerate(batches[:third]):
            post_batch(a if k % 2 == 0 else b, batch)
        wait_tracked(postgres_url)  # the leader is idle: it holds no transaction open
        os.kill(leader.pid, signal.SIGSTOP)
        try:
            for batch in batches[third : 2 * third]:
                post_batch(b, batch)
            wait_tracked(postgres_url)  # the follower took over
            assert f":{follower.pid}:" in _holder(postgres_url)
        finally:
            os.kill(leader.pid, signal.SIGCONT)
        for k, batch in enumerate(batches[2 * third :]):  # the old leader gets batches at once
            post_batch(a if k % 2 == 0 else b, batch)
        wait_tracked(postgres_url)
        assert f":{follower.pid}:" in _holder(postgres_url)
        assert get_json(a, "/api/tracks") == reference
        assert get_json(b, "/api/tracks") == reference
        assert "stops tracking" in log_text(tmp_path, "a")
        assert "stops tracking" not in log_text(tmp_path, "b")
    finally:
        stop(leader)
        if follower is not None:
            stop(follower)
