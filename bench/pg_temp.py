"""Throw-away PostgreSQL databases for the benchmarks: a temporary server, or a given one.

:func:`temp_server` starts a PostgreSQL server of its own (``initdb`` and ``pg_ctl`` of
Debian's ``postgresql-15`` into a temporary folder, loopback, a free port; as root it
runs as the ``postgres`` user through ``runuser``, since PostgreSQL refuses root) and
stops it afterwards. :func:`fresh_database` makes an empty database on the server of a
URL (its role needs ``CREATEDB``) and drops it afterwards, so a benchmark always starts
from an empty store, as the SQLite one starts from a new file.
"""

from __future__ import annotations

import contextlib
import glob
import os
import pwd
import shutil
import socket
import subprocess
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

__all__ = ["fresh_database", "temp_server"]


def _pg_bin() -> Path:
    for candidate in sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True):
        if Path(candidate, "initdb").exists():
            return Path(candidate)
    found = shutil.which("pg_ctl")
    if found is None:
        raise RuntimeError(
            "PostgreSQL is not installed (apt-get install postgresql-15 postgresql-15-postgis-3);"
            " or give --database-url"
        )
    return Path(found).parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@contextlib.contextmanager
def temp_server(root: Path) -> Iterator[str]:
    """A PostgreSQL server in ``root`` for the ``with`` block; its ``postgres`` database URL.

    ``fsync`` stays on and ``synchronous_commit`` at its default (on): the figures are
    those of a durable server.
    """
    bin_dir, port = _pg_bin(), _free_port()
    data, sock = root / "data", root / "socket"
    sock.mkdir(parents=True, exist_ok=True)
    as_postgres = os.geteuid() == 0
    if as_postgres:
        pw = pwd.getpwnam("postgres")
        for path in (root, sock):
            os.chown(path, pw.pw_uid, pw.pw_gid)
        parent = root
        while parent != parent.parent:  # runuser must be able to reach the folder
            parent.chmod(parent.stat().st_mode | 0o005)
            parent = parent.parent

    def run(*args: str) -> None:
        cmd = ["runuser", "-u", "postgres", "--", *args] if as_postgres else list(args)
        subprocess.run(cmd, check=True, capture_output=True, text=True)

    run(str(bin_dir / "initdb"), "-D", str(data), "-U", "demtrack", "--auth=trust", "--no-sync")
    options = (
        f"-c listen_addresses=127.0.0.1 -c port={port} -c unix_socket_directories={sock}"
        " -c fsync=on -c shared_buffers=128MB"
    )
    ctl = str(bin_dir / "pg_ctl")
    run(ctl, "-D", str(data), "-o", options, "-l", str(root / "server.log"), "-w", "start")
    try:
        yield f"postgresql://demtrack@127.0.0.1:{port}/postgres"
    finally:
        with contextlib.suppress(subprocess.CalledProcessError):
            run(ctl, "-D", str(data), "-m", "fast", "stop")


@contextlib.contextmanager
def fresh_database(url: str) -> Iterator[str]:
    """A new empty database on ``url``'s server for the ``with`` block (dropped after)."""
    import psycopg

    name = f"demtrack_bench_{uuid.uuid4().hex[:10]}"
    deadline = time.monotonic() + 30
    while True:
        try:
            admin = psycopg.connect(url, autocommit=True, connect_timeout=5)
            break
        except psycopg.OperationalError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
    with admin:
        admin.execute(f'CREATE DATABASE "{name}"')  # type: ignore[call-overload]
    parts = urlsplit(url)
    try:
        yield urlunsplit((parts.scheme, parts.netloc, "/" + name, parts.query, parts.fragment))
    finally:
        with psycopg.connect(url, autocommit=True) as admin:
            admin.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')  # type: ignore[call-overload]
