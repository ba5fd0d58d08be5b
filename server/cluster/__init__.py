"""Several server processes on one PostgreSQL database (issue 30).

Every process stores and acknowledges the batches posted to it and serves consoles;
exactly one, the holder of the site lease, tracks (:mod:`.role`), and a stale holder's
writes are refused by the lease's fencing token (:mod:`.lease`). Every process publishes
the stream from the shared event log (:mod:`.event_tail`), so a console on any process
sees every message once, in order. :mod:`.node` wires them into the app. SQLite stays
one process: nothing here runs on it.

May import :mod:`demtrack.server.ingest` and :mod:`demtrack.server.store` (and psycopg);
nothing in the ingest pipeline, the store or the routers imports it.
"""

from __future__ import annotations

__all__: list[str] = []
