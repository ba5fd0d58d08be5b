"""The site lease: one tracker per site among server processes on one PostgreSQL database.

A row of ``site_lease`` names the process (``owner``) that tracks a site until
``expires_at`` (the database's clock, so the processes' clocks never matter) and a
fencing ``token`` that grows whenever ownership changes hands. The holder renews the row
well before it expires; another process takes it over only once it has expired. A
holder that stalled past its expiry (a long pause, a lost network) may still believe it
leads: every derived write it makes carries :meth:`SiteLease.fence_check`, which reads
the row ``FOR SHARE`` inside the write's own transaction and refuses the write when the
token is no longer the writer's (:class:`FencedOut`). The share lock also holds off a
takeover until that transaction ends, so a new holder always starts from a state that
includes every write the old one made.

Tokens: the first holder of a site gets 1; a new token (the previous one + 1) is given
whenever the lease is acquired after it expired or was released, even by the owner that
held it before (that owner stopped tracking in between and starts over). Acquiring a
lease one already holds and that is live keeps its token (a renewal).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from ..store.integrity import StoreUnavailableError

__all__ = ["FencedOut", "LEASE_LOCK", "LEASE_TABLE", "SiteLease"]

#: The lease table (created on first use; PostgreSQL only).
LEASE_TABLE = """
CREATE TABLE IF NOT EXISTS site_lease (
    site_id text PRIMARY KEY,
    owner text NOT NULL,
    token bigint NOT NULL,
    expires_at timestamptz NOT NULL
)
"""

#: The advisory lock under which the table is created (``"demtrack" 4``, beside the
#: store's own keys).
LEASE_LOCK = 0x64656D_0004

_ACQUIRE = """
INSERT INTO site_lease AS l (site_id, owner, token, expires_at)
VALUES (%(site)s, %(owner)s, 1, now() + make_interval(secs => %(ttl)s))
ON CONFLICT (site_id) DO UPDATE SET
    owner = EXCLUDED.owner,
    token = CASE WHEN l.owner = EXCLUDED.owner AND l.expires_at > now()
                 THEN l.token ELSE l.token + 1 END,
    expires_at = EXCLUDED.expires_at
WHERE l.expires_at <= now() OR l.owner = EXCLUDED.owner
RETURNING token
"""

_RENEW = """
UPDATE site_lease SET expires_at = now() + make_interval(secs => %(ttl)s)
WHERE site_id = %(site)s AND owner = %(owner)s AND token = %(token)s AND expires_at > now()
RETURNING token
"""

_RELEASE = """
UPDATE site_lease SET expires_at = now()
WHERE site_id = %(site)s AND owner = %(owner)s AND token = %(token)s
"""

_FENCE = "SELECT token FROM site_lease WHERE site_id = %s FOR SHARE"


class FencedOut(StoreUnavailableError):
    """A derived write by a process whose lease token is no longer the site's current one.

    The write's transaction was rolled back: another process tracks the site now. It can
    never pass (its fence holds the old token), so it is not held for a retry.
    """

    retryable = False


class SiteLease:
    """The ``site_lease`` table on one PostgreSQL database (its own connection).

    Parameters
    ----------
    url : str
        The database's ``postgresql://`` URL.
    connect : callable, optional
        ``connect(url)`` -> an autocommit psycopg connection (the default opens one).
    lock_timeout_s : float
        Longest wait of a call for the lease row (s): a holder's write transaction
        keeps it share-locked, and a holder paused inside one (a stopped process) would
        otherwise hold a takeover attempt indefinitely; the attempt fails instead
        (``psycopg.errors.LockNotAvailable``) and is retried.

    Notes
    -----
    Calls are serialised on the connection (a lock): the keeper's renewals and a
    server's shutdown release may come from different threads.
    """

    def __init__(
        self,
        url: str,
        connect: Callable[[str], Any] | None = None,
        lock_timeout_s: float = 5.0,
    ) -> None:
        import psycopg

        self.url = url
        self._conn = (
            connect(url)
            if connect is not None
            else psycopg.connect(url, autocommit=True, application_name="demtrack-lease")
        )
        self._lock = threading.Lock()
        with self._lock:
            self._conn.execute(f"SET lock_timeout = {int(lock_timeout_s * 1000)}")
            with self._conn.transaction():  # two processes starting at once: one creates it
                self._conn.execute("SELECT pg_advisory_xact_lock(%s)", (LEASE_LOCK,))
                self._conn.execute(LEASE_TABLE)

    def close(self) -> None:
        """Close the connection (a held lease is left to expire: call :meth:`release`)."""
        with self._lock:
            self._conn.close()

    def _one(self, sql: str, params: dict[str, Any]) -> Any:
        with self._lock:
            row = self._conn.execute(sql, params).fetchone()
        return None if row is None else row[0]

    def acquire(self, site_id: str, owner: str, ttl_s: float) -> int | None:
        """Take (or keep) the lease of ``site_id`` for ``ttl_s`` seconds; its token.

        None while another owner holds a live lease. See the module docstring for when
        the token changes.
        """
        token = self._one(_ACQUIRE, {"site": site_id, "owner": owner, "ttl": float(ttl_s)})
        return None if token is None else int(token)

    def renew(self, site_id: str, owner: str, token: int, ttl_s: float) -> bool:
        """Extend a live lease held with ``token`` to ``ttl_s`` from now; False if lost.

        An expired lease is not renewed, even when nobody took it: its holder must stop
        and :meth:`acquire` again (a new token).
        """
        params = {"site": site_id, "owner": owner, "token": int(token), "ttl": float(ttl_s)}
        return self._one(_RENEW, params) is not None

    def release(self, site_id: str, owner: str, token: int) -> None:
        """Give the lease up now (a clean shutdown): another process may take it at once."""
        with self._lock:
            self._conn.execute(_RELEASE, {"site": site_id, "owner": owner, "token": int(token)})

    def holder(self, site_id: str) -> tuple[str, int, bool] | None:
        """``(owner, token, live)`` of the site's lease row, None when there is none."""
        with self._lock:
            row = self._conn.execute(
                "SELECT owner, token, expires_at > now() FROM site_lease WHERE site_id = %s",
                (site_id,),
            ).fetchone()
        return None if row is None else (str(row[0]), int(row[1]), bool(row[2]))

    @staticmethod
    def fence_check(
        site_id: str, token: int, on_stale: Callable[[], None] | None = None
    ) -> Callable[[Any], None]:
        """The fence of a derived write made while holding ``token``.

        Returns ``fence(conn)``, to be called inside the write's transaction on ``conn``
        before it writes: it reads the lease row ``FOR SHARE`` and raises
        :class:`FencedOut` (after calling ``on_stale()``, when given) unless the row's
        token is ``token``.
        """

        def fence(conn: Any) -> None:
            row = conn.execute(_FENCE, (site_id,)).fetchone()
            current = None if row is None else int(row[0])
            if current != token:
                if on_stale is not None:
                    on_stale()
                raise FencedOut(
                    f"lease of site {site_id!r} lost (token {token}, now"
                    f" {current if current is not None else 'none'}): another process"
                    " tracks it; this one stops tracking"
                )

        return fence
