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
