"""The store on PostgreSQL + PostGIS: several server processes on one database.

:class:`~.database.PostgresStore` has the SQLite store's whole surface
(:class:`~demtrack.server.store.backend.StoreBackend`) and shares its read SQL
(:mod:`demtrack.server.store.reading`), its batch inserts and derived-row writers
(:mod:`~demtrack.server.store.batches`, :mod:`~demtrack.server.store.derived`) and its
codec, so an API answer is the same text from either database. What differs lives here:

:mod:`.connection`  psycopg 3 connections, ``?`` placeholders, URLs without passwords
:mod:`.schema`      the same migrations 1..7 in PostgreSQL's SQL, with PostGIS columns
:mod:`.dialect`     upserts, the event log's numbering and its ``pg_notify``
:mod:`.database`    :class:`~.database.PostgresStore`

Geometry is in the site's local metric frame (x east, y north, metres; SRID 0, the
frame of every ``e_m``/``n_m`` the store holds): fixes (their first hit), track points,
activity (its ``p_enu``) and markers as Points, tracks as LineStrings, each with a GiST
index. They are additional columns, filled by the database from the stored JSON; no
answer is read from them. See docs/postgres.md.

May import :mod:`demtrack.server.store`'s modules and ``demtrack.core``.
"""
