"""A real PostgreSQL server for the tests: ``initdb`` and ``pg_ctl`` into a temporary folder.

Debian's ``postgresql-15`` and ``postgresql-15-postgis-3`` packages give the binaries
(``.ci/run`` installs them). The server listens on loopback at a free port and on a Unix
socket in its own folder, trusts local connections and is stopped when the test session
ends. PostgreSQL refuses to run as root: as root the cluster runs as the ``postgres`` user
(made by the Debian package) through ``runuser``.

``PostgresCluster.create_database()`` gives each test its own empty database (with the
PostGIS extension available; the store's first migration creates it).
``PostgresCluster.create_store_database()`` gives one already migrated, cloned from a
template database migrated once per session (``CREATE DATABASE ... TEMPLATE``: about 0.3 s
instead of the 2 s the migrations take); the template holds no ``store_identity`` row, so
each clone gets its own random store id when a store first opens it.
"""

from __future__ import annotations

import glob
import os
import pwd
import shutil
import socket
import subprocess
import time
import uuid
from pathlib import Path

__all__ = ["PostgresCluster", "find_pg_bin"]


def find_pg_bin() -> Path | None:
    """The folder with ``initdb`` and ``pg_ctl`` (newest Debian version first), or None."""
    for candidate in sorted(glob.glob("/usr/lib/postgresql/*/bin"), reverse=True):
        if Path(candidate, "initdb").exists() and Path(candidate, "pg_ctl").exists():
            return Path(candidate)
    found = shutil.which("pg_ctl")
    return Path(found).parent if found else None


def _free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class PostgresCluster:
    """One throw-away PostgreSQL server; ``url`` connects to its ``postgres`` database."""

    def __init__(self, root: Path, bin_dir: Path | None = None) -> None:
        found = bin_dir or find_pg_bin()
        if found is None:
            raise RuntimeError("PostgreSQL is not installed (apt-get install postgresql-15)")
        self.bin = found
        self.root = Path(root)
        self.data = self.root / "data"
        self.socket_dir = self.root / "socket"
        self.port = _free_port()
        self.user = "demtrack"
        self._as_postgres = os.geteuid() == 0
        self._template: str | None = None

    # -- running the binaries ------------------------------------------------------------
    def _cmd(self, *args: str) -> list[str]:
        if self._as_postgres:
            return ["runuser", "-u", "postgres", "--", *args]
        return list(args)

    def _run(self, *args: str) -> None:
        subprocess.run(self._cmd(*args), check=True, capture_output=True, text=True)

    def start(self) -> PostgresCluster:
        """initdb, then start the server and wait until it accepts connections."""
        self.root.mkdir(parents=True, exist_ok=True)
        self.socket_dir.mkdir(exist_ok=True)
        if self._as_postgres:
            pw = pwd.getpwnam("postgres")
            for path in (self.root, self.socket_dir):
                os.chown(path, pw.pw_uid, pw.pw_gid)
            self.root.chmod(0o755)
            parent = self.root.parent  # runuser must be able to reach the folder
            while parent != parent.parent:
                parent.chmod(parent.stat().st_mode | 0o005)
                parent = parent.parent
        self._run(
            str(self.bin / "initdb"),
            "-D",
            str(self.data),
            "-U",
            self.user,
            "--auth=trust",
            "--encoding=UTF8",
            "--locale=C",
            "--no-sync",
        )
        options = (
            f"-c listen_addresses=127.0.0.1 -c port={self.port} "
            f"-c unix_socket_directories={self.socket_dir} -c max_connections=200 "
            "-c fsync=on -c shared_buffers=64MB"
        )
        self._run(
            str(self.bin / "pg_ctl"),
            "-D",
            str(self.data),
            "-o",
            options,
            "-l",
            str(self.root / "server.log"),
            "-w",
            "-t",
            "60",
            "start",
        )
        self._wait_ready()
        return self

    def _wait_ready(self, timeout_s: float = 30.0) -> None:
        import psycopg

        deadline = time.monotonic() + timeout_s
        while True:
            try:
                with psycopg.connect(self.url, connect_timeout=2):
                    return
            except psycopg.OperationalError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    def stop(self) -> None:
        """Stop the server (fast shutdown); the folder is left to the caller."""
        if self.data.exists():
            subprocess.run(
                self._cmd(str(self.bin / "pg_ctl"), "-D", str(self.data), "-m", "fast", "stop"),
                capture_output=True,
                check=False,
            )

    # -- databases -----------------------------------------------------------------------
    @property
    def url(self) -> str:
        return self.database_url("postgres")

    def database_url(self, name: str) -> str:
        return f"postgresql://{self.user}@127.0.0.1:{self.port}/{name}"

    def create_database(self, prefix: str = "t", template: str | None = None) -> str:
        """A new database, empty or a copy of ``template`` (a database name); its URL."""
        import psycopg

        name = f"{prefix}_{uuid.uuid4().hex[:12]}"
        clause = f' TEMPLATE "{template}"' if template else ""
        with psycopg.connect(self.url, autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"{clause}')
        return self.database_url(name)

    def create_store_database(self) -> str:
        """A new database holding the store's current schema and no rows; its URL."""
        if self._template is None:
            import psycopg

            from demtrack.server.store.postgres.database import PostgresStore

            url = self.create_database("template")
            PostgresStore(url).close()  # every migration
            with psycopg.connect(url, autocommit=True) as conn:
                conn.execute("DELETE FROM store_identity")  # each clone makes its own
            self._template = url.rsplit("/", 1)[1]
        return self.create_database("s", template=self._template)
