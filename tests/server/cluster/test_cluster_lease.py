"""The site lease on a real PostgreSQL: owners, expiry, monotonic tokens, fencing."""

from __future__ import annotations

import threading
import time

import psycopg
import pytest

from demtrack.server.cluster.lease import FencedOut, SiteLease


@pytest.fixture
def lease(postgres_url: str):
    out = SiteLease(postgres_url)
    yield out
    out.close()


def _expire(url: str, site: str) -> None:
    """Make the site's lease expired now, as if its holder had stopped renewing."""
    with psycopg.connect(url, autocommit=True) as c:
        c.execute(
            "UPDATE site_lease SET expires_at = now() - interval '1 second' WHERE site_id = %s",
            (site,),
        )


def test_one_owner_at_a_time(lease: SiteLease) -> None:
    assert lease.acquire("s", "a", 30) == 1
    assert lease.acquire("s", "b", 30) is None  # a holds it
    assert lease.acquire("s", "a", 30) == 1  # a live holder keeps its token
    assert lease.holder("s") == ("a", 1, True)
    assert lease.acquire("other-site", "b", 30) == 1  # sites are independent


def test_a_second_process_sees_the_same_lease(lease: SiteLease, postgres_url: str) -> None:
    other = SiteLease(postgres_url)  # its own connection: another process's view
    try:
        assert lease.acquire("s", "a", 30) == 1
        assert other.acquire("s", "b", 30) is None
        assert other.holder("s") == ("a", 1, True)
    finally:
        other.close()


def test_expiry_hands_the_lease_over(lease: SiteLease) -> None:
    assert lease.acquire("s", "a", 0.3) == 1
    deadline = time.monotonic() + 30
    token = None
    while token is None and time.monotonic() < deadline:  # the database's clock decides
        token = lease.acquire("s", "b", 30)
        time.sleep(0.05)
    assert token == 2
    assert not lease.renew("s", "a", 1, 30)  # the old holder cannot renew
    assert lease.acquire("s", "a", 30) is None
    assert lease.renew("s", "b", 2, 30)


def test_renew_keeps_a_live_lease_and_refuses_an_expired_one(
    lease: SiteLease, postgres_url: str
) -> None:
    assert lease.acquire("s", "a", 30) == 1
    assert lease.renew("s", "a", 1, 30)
    assert not lease.renew("s", "a", 7, 30)  # not its token
    assert not lease.renew("s", "b", 1, 30)  # not its owner
    _expire(postgres_url, "s")
    assert not lease.renew("s", "a", 1, 30)  # expired, though nobody took it
    assert lease.acquire("s", "a", 30) == 2  # back again: a new token


def test_tokens_grow_with_every_change_of_hands(lease: SiteLease, postgres_url: str) -> None:
    tokens = []
    for k in range(6):
        owner = "ab"[k % 2]
        token = lease.acquire("s", owner, 30)
        assert token is not None
        tokens.append(token)
        if k % 3 == 2:
            _expire(postgres_url, "s")
        else:
            lease.release("s", owner, token)
    assert tokens == sorted(set(tokens))
    assert tokens == list(range(1, 7))
    # releasing with a stale token changes nothing
    current = lease.acquire("s", "a", 30)
    lease.release("s", "a", tokens[0])
    assert lease.holder("s") == ("a", current, True)


def test_fence_rejects_a_stale_token_inside_the_write_transaction(
    lease: SiteLease, postgres_url: str
) -> None:
    old = lease.acquire("s", "a", 30)
    assert old is not None
    lease.release("s", "a", old)
    new = lease.acquire("s", "b", 30)
    assert new == old + 1
    stale: list[bool] = []
    with psycopg.connect(postgres_url) as conn:
        conn.execute("CREATE TABLE derived (x int)")
        conn.commit()
        with pytest.raises(FencedOut, match="lease of site 's' lost"):
            with conn.transaction():
                SiteLease.fence_check("s", old, on_stale=lambda: stale.append(True))(conn)
                conn.execute("INSERT INTO derived VALUES (1)")
        with conn.transaction():
            SiteLease.fence_check("s", new)(conn)
            conn.execute("INSERT INTO derived VALUES (2)")
        assert conn.execute("SELECT x FROM derived").fetchall() == [(2,)]
    assert stale == [True]


def test_fence_of_a_site_without_lease_rejects(postgres_url: str, lease: SiteLease) -> None:
    with psycopg.connect(postgres_url) as conn:
        with pytest.raises(FencedOut, match="now none"):
            with conn.transaction():
                SiteLease.fence_check("nowhere", 1)(conn)


def test_an_open_fenced_write_holds_off_the_takeover(lease: SiteLease, postgres_url: str) -> None:
    """A write that passed its fence commits before anyone can take the lease over."""
    token = lease.acquire("s", "a", 30)
    assert token is not None
    writer = psycopg.connect(postgres_url)
    writer.execute("CREATE TABLE derived (x int)")
    writer.commit()
    _expire(postgres_url, "s")  # expired, but nobody took it yet: the token is still a's
    SiteLease.fence_check("s", token)(writer)  # the write's transaction is now open
    writer.execute("INSERT INTO derived VALUES (1)")
    impatient = SiteLease(postgres_url)
    impatient._conn.execute("SET lock_timeout = '300ms'")  # noqa: SLF001
    with pytest.raises(psycopg.errors.LockNotAvailable):
        impatient.acquire("s", "b", 30)  # blocked by the writer's FOR SHARE
    impatient.close()
    got: list[int | None] = []
    taker = SiteLease(postgres_url)
    t = threading.Thread(target=lambda: got.append(taker.acquire("s", "b", 30)))
    t.start()
    writer.commit()  # the old holder's write lands first
    t.join(30)
    taker.close()
    assert got == [token + 1]
    with psycopg.connect(postgres_url) as c:
        assert c.execute("SELECT x FROM derived").fetchall() == [(1,)]
    writer.close()
