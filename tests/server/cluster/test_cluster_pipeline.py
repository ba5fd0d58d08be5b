"""Two pipelines on one PostgreSQL database, in one test process: roles and fencing, step by step.

Each pipeline has its own store (its own connections), as two server processes would.
The oracle is one pipeline that ingested the same batches in the same order.
"""

from __future__ import annotations

from pathlib import Path

import psycopg
import pytest
from cluster_helpers import scenario_batches

from demtrack.core.site.folder import load_site
from demtrack.server.cluster.lease import SiteLease
from demtrack.server.ingest.pipeline import Pipeline
from demtrack.server.store.opening import open_store

UNTIL_S = 20.0


@pytest.fixture(scope="module")
def site(sample_site_dir: Path):
    return load_site(sample_site_dir)


@pytest.fixture(scope="module")
def batches(site) -> list[list[dict]]:
    return scenario_batches(site, UNTIL_S)


def _pipeline(site, url: str) -> Pipeline:
    return Pipeline(site, open_store(url), "kalman", lambda _m: None)


@pytest.fixture(scope="module")
def reference(site, postgres_cluster, batches) -> list[dict]:
    """The tracks of one pipeline that ingested every batch in order."""
    p = _pipeline(site, postgres_cluster.create_database())
    p.start()
    for b in batches:
        p.ingest(b)
    out = p.store.tracks()
    p.store.close()
    return out


def _n_fixes(url: str) -> int:
    with psycopg.connect(url, autocommit=True) as c:
        return int(c.execute("SELECT count(*) FROM fixes").fetchone()[0])


def _expire(url: str) -> None:
    with psycopg.connect(url, autocommit=True) as c:
        c.execute("UPDATE site_lease SET expires_at = now() - interval '1 second'")


def test_follower_stores_only_and_the_leader_takes_its_batches_in_id_order(
    site, postgres_url: str, batches, reference
) -> None:
    lease = SiteLease(postgres_url)
    leader, follower = _pipeline(site, postgres_url), _pipeline(site, postgres_url)
    token = lease.acquire("s", "leader", 60)
    assert token is not None
    leader.lead(SiteLease.fence_check("s", token))
    follower.follow()
    for k, b in enumerate(batches):
        if k % 2:
            ack = follower.ingest(b)
            assert ack["accepted"] == len(b) and not follower.tracking
            assert _n_fixes(postgres_url) < sum(len(x) for x in batches[: k + 1])
        else:
            leader.ingest(b)  # takes the follower's batch before it first
    leader.catch_up()  # the last batches the follower stored
    assert _n_fixes(postgres_url) == sum(len(x) for x in batches)
    assert leader.store.tracks() == reference
    assert follower.store.tracks() == reference  # one database: one answer
    lease.close()


def test_a_stale_leader_writes_nothing_and_the_new_one_tracks_its_batch(
    site, postgres_url: str, batches, reference
) -> None:
    lease = SiteLease(postgres_url)
    old, new = _pipeline(site, postgres_url), _pipeline(site, postgres_url)
    t_old = lease.acquire("s", "old", 60)
    assert t_old is not None
    lost: list[bool] = []

    def stale() -> None:
        lost.append(True)
        old.tracking = False

    old.lead(SiteLease.fence_check("s", t_old, on_stale=stale))
    new.follow()
    half = len(batches) // 2
    for k, b in enumerate(batches[:half]):
        (old if k % 2 == 0 else new).ingest(b)
    old.catch_up()
    # The old leader stalls past its lease (it never learns); the other takes over.
    _expire(postgres_url)
    t_new = lease.acquire("s", "new", 60)
    assert t_new == t_old + 1
    new.lead(SiteLease.fence_check("s", t_new))
    before = _n_fixes(postgres_url)
    assert old.tracking  # it still believes it tracks
    ack = old.ingest(batches[half])  # stored and acknowledged; its tracking refused
    assert ack["accepted"] == len(batches[half])
    assert lost == [True] and not old.tracking
    assert _n_fixes(postgres_url) == before  # no write landed with the stale token
    for k, b in enumerate(batches[half + 1 :]):
        (new if k % 2 == 0 else old).ingest(b)
    new.catch_up()
    assert _n_fixes(postgres_url) == sum(len(x) for x in batches)
    assert new.store.tracks() == reference
    lease.close()


def test_sqlite_pipeline_is_untouched_by_the_cluster_hooks(site, tmp_path: Path, batches) -> None:
    """One process on SQLite: tracks every batch itself, no fence, no catch-up."""
    p = _pipeline(site, str(tmp_path / "one.sqlite3"))
    p.start()
    assert p.tracking and p.fence is None and p.tail_after is None
    assert p.catch_up() == 0
    p.ingest(batches[0])
    assert len(p.store.fixes(0, 10_000)) == len(batches[0])


def test_a_group_committed_one_by_one_leaves_no_batch_of_another_process_behind(
    site, postgres_url: str, batches
) -> None:
    """A group whose shared transaction failed is committed batch by batch; another
    process's batch committed between two of them is still tracked, in id order."""
    from demtrack.server.ingest.group_commit import Request

    lease = SiteLease(postgres_url)
    leader, follower = _pipeline(site, postgres_url), _pipeline(site, postgres_url)
    token = lease.acquire("s", "leader", 60)
    assert token is not None
    leader.lead(SiteLease.fence_check("s", token))
    follower.follow()
    store = leader.store
    insert = store.insert_batches
    calls: list[int] = []

    def flaky(entries):  # the group's shared transaction fails; between retries, another
        calls.append(len(entries))  # process commits a batch
        if len(calls) == 1:
            raise RuntimeError("the shared transaction failed")
        out = insert(entries)
        if len(calls) == 2:
            follower.ingest(batches[1])
        return out

    store.insert_batches = flaky  # type: ignore[method-assign]
    with leader._lock:  # noqa: SLF001 - the group commit's own call, made by hand
        leader._ingest_group([Request(batches[0], None), Request(batches[2], None)])  # noqa: SLF001
    store.insert_batches = insert  # type: ignore[method-assign]
    assert calls == [2, 1, 1]
    n = sum(len(b) for b in batches[:3])
    assert _n_fixes(postgres_url) == n  # the follower's batch between them too
    with psycopg.connect(postgres_url, autocommit=True) as c:
        ids = [r[0] for r in c.execute("SELECT id FROM detections ORDER BY id")]
    assert ids == list(range(1, n + 1))
    lease.close()


def _rays(store) -> dict[int, tuple[bool, list[float]]]:
    return {
        b["detection_id"]: (bool(b["hits"]), b["origin_enu"] + b["direction_enu"])
        for b in store.fixes(0, 100_000)
    }


def test_poses_a_follower_stored_pose_the_leaders_detections(site, postgres_cluster) -> None:
    """A PTZ head's telemetry posted to one process, its detections to another.

    Oracle: one pipeline that took both. Before the leader read other processes' poses it
    geolocated these detections at the head's fixed pose (rays 4 degrees off).
    """
    from server_helpers import walk

    from demtrack.core.camera.pose_series import PoseSample

    cam = site.sensors["cam1"]
    pan, tilt = cam.pan_deg + 4.0, cam.tilt_deg - 1.5
    poses = [PoseSample(k * 0.1, pan, tilt) for k in range(80)]
    dets = walk(n=30, t0=0.0, dt=0.2)
    oracle = _pipeline(site, postgres_cluster.create_database())
    oracle.start()
    oracle.ingest_poses("cam1", poses)
    oracle.ingest(dets)
    want = _rays(oracle.store)

    url = postgres_cluster.create_database()
    lease = SiteLease(url)
    leader, follower = _pipeline(site, url), _pipeline(site, url)
    token = lease.acquire("s", "leader", 60)
    assert token is not None
    leader.lead(SiteLease.fence_check("s", token))
    follower.follow()
    assert follower.ingest_poses("cam1", poses)["accepted"] == len(poses)
    assert follower.ingest(dets)["accepted"] == len(dets)
    leader.catch_up()
    got = _rays(leader.store)
    assert sorted(got) == sorted(want) and len(got) == len(dets)
    assert [got[k][0] for k in sorted(got)] == [want[k][0] for k in sorted(want)]
    hit = [k for k in sorted(want) if want[k][0]]
    assert len(hit) > 20
    for k in hit:
        assert got[k][1] == pytest.approx(want[k][1], abs=1e-9)
    assert leader.pose_book.newest["cam1"].t_s == pytest.approx(poses[-1].t_s)
    for p in (oracle, leader, follower):
        p.store.close()
    lease.close()
