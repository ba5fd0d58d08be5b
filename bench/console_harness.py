"""What the console benchmarks share: a ``demtrack serve`` process and headless Chromium.

:class:`ServeProcess` runs the real CLI on a free loopback port (as an operator would)
and waits for ``/api/health``; :func:`launch_chromium` starts Debian's Chromium headless
with the arguments that work on these machines (docs/console.md, the browser tests).
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["CHROMIUM", "LAUNCH_ARGS", "ServeProcess", "free_port", "launch_chromium"]

CHROMIUM = Path("/usr/bin/chromium")
LAUNCH_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def free_port() -> int:
    """A loopback port free right now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@dataclass
class ServeProcess:
    """A ``demtrack serve`` process on loopback.

    Parameters
    ----------
    site : Path
        Built site folder.
    db : Path
        SQLite file (a fresh one gives a fresh stream).
    token : str
        Operator token (``DEMTRACK_TOKEN``).
    args : sequence of str
        More ``demtrack serve`` arguments (``--replay``, ``--speed``, ...).
    env : dict
        More environment variables (``DEMTRACK_*`` settings).
    port : int
        Port to bind (default: a free one).
    """

    site: Path
    db: Path
    token: str
    args: Sequence[str] = ()
    env: dict[str, str] = field(default_factory=dict)
    port: int = field(default_factory=free_port)
    proc: subprocess.Popen | None = None
    _log: Any = field(default=None, repr=False)

    @property
    def url(self) -> str:
        """Base URL of the server."""
        return f"http://127.0.0.1:{self.port}"

    @property
    def pid(self) -> int:
        """Process id of the server (it runs in this process's Python, no shell)."""
        if self.proc is None:
            raise RuntimeError("the server is not running")
        return int(self.proc.pid)

    def start(self, timeout_s: float = 300.0) -> ServeProcess:
        """Start the server and wait until ``/api/health`` answers."""
        import httpx2 as httpx

        cmd = [sys.executable, "-m", "demtrack.cli", "serve", "--site", str(self.site)]
        cmd += ["--db", str(self.db), "--port", str(self.port), "--log-level", "warning"]
        self._log = tempfile.TemporaryFile()  # stderr, for the message if it fails
        self.proc = subprocess.Popen(
            [*cmd, *self.args],
            env={**os.environ, "DEMTRACK_TOKEN": self.token, **self.env},
            stdout=subprocess.DEVNULL,
            stderr=self._log,
        )
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                self._log.seek(0)
                tail = self._log.read().decode("utf-8", "replace").strip().splitlines()[-15:]
                raise RuntimeError(
                    f"the server exited with status {self.proc.returncode}:\n" + "\n".join(tail)
                )
            try:
                if httpx.get(f"{self.url}/api/health", timeout=2).status_code == 200:
                    return self
            except httpx.TransportError:
                time.sleep(0.3)
        self.stop()
        raise RuntimeError("the server did not start")

    def stop(self) -> None:
        """Terminate the server (SIGTERM, then SIGKILL after 30 s)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self.proc = None
        if self._log is not None:
            self._log.close()
            self._log = None

    def client(self, timeout_s: float = 120.0) -> Any:
        """An ``httpx`` client on the server with the token."""
        import httpx2 as httpx

        auth = {"Authorization": f"Bearer {self.token}"}
        return httpx.Client(base_url=self.url, headers=auth, timeout=timeout_s)


def launch_chromium(playwright: Any) -> Any:
    """Debian's Chromium, headless, from a Playwright (sync) instance."""
    return playwright.chromium.launch(
        executable_path=str(CHROMIUM), headless=True, args=LAUNCH_ARGS
    )
