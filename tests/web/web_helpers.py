"""Helpers of the browser tests (imported by file name: tests are not a package)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import httpx2 as httpx

# The browser and port set-up the benchmarks use, re-exported for the tests.
from demtrack.bench.console_harness import CHROMIUM as CHROMIUM
from demtrack.bench.console_harness import LAUNCH_ARGS as LAUNCH_ARGS
from demtrack.bench.console_harness import free_port as free_port

REPO = Path(__file__).resolve().parents[2]
OL_JS = REPO / "web" / "node_modules" / "ol" / "dist" / "ol.js"
SHOTS = REPO / "test-artifacts" / "web"
TOKEN = "web-test-operator-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
SCENARIO = "passing-vehicles"
LOOPBACK = {"127.0.0.1", "localhost", "::1", "[::1]"}


def wait_until(fn: Any, timeout_s: float = 60.0, every_s: float = 0.25, page: Any = None) -> Any:
    """``fn()`` until it returns something truthy or ``timeout_s`` passes: its last value.

    With ``page``, the pause between tries is the page's ``wait_for_timeout``, so that
    Playwright goes on dispatching the page's events meanwhile (``time.sleep`` blocks them).
    """
    deadline = time.monotonic() + timeout_s
    while True:
        out = fn()
        if out or time.monotonic() > deadline:
            return out
        if page is None:
            time.sleep(every_s)
        else:
            page.wait_for_timeout(1000 * every_s)


@dataclass
class Server:
    """A ``demtrack serve`` process."""

    site: Path
    db: Path
    port: int
    proc: subprocess.Popen | None = None
    log: list[str] = field(default_factory=list)
    extra_args: tuple[str, ...] = ()  # more `demtrack serve` options, e.g. ("--3d",)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    def start(self, timeout_s: float = 180.0) -> Server:
        env = {**os.environ, "DEMTRACK_TOKEN": TOKEN}
        self.proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "demtrack.cli",
                "serve",
                "--site",
                str(self.site),
                "--db",
                str(self.db),
                "--port",
                str(self.port),
                "--no-warm-up",
                "--log-level",
                "warning",
                *self.extra_args,
            ],
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            env=env,
        )
        assert self.proc.stdout is not None
        threading.Thread(target=self._drain, args=(self.proc.stdout,), daemon=True).start()
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                raise AssertionError("server exited:\n" + "".join(self.log[-40:]))
            try:
                if httpx.get(f"{self.url}/api/health", timeout=2).status_code == 200:
                    return self
            except httpx.TransportError:
                pass
            time.sleep(0.2)
        self.stop()
        raise AssertionError("server did not start:\n" + "".join(self.log[-40:]))

    def _drain(self, pipe: Any) -> None:
        for line in pipe:
            self.log.append(line)
            del self.log[:-200]

    def stop(self, sig: int = signal.SIGTERM) -> None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(10)
        self.proc = None

    def client(self) -> httpx.Client:
        return httpx.Client(base_url=self.url, headers=AUTH, timeout=60)


def post_records(client: httpx.Client, records: list[dict[str, Any]], key: str) -> None:
    """Ingest ``records`` in one batch (``key`` makes a resend harmless)."""
    resp = client.post("/api/detections", json={"batch_key": key, "detections": records})
    assert resp.status_code == 200, resp.text
    assert resp.json()["skipped"] == 0, resp.json()


def post_until(
    client: httpx.Client, records: list[dict[str, Any]], t0: float, t1: float, step_s: float = 2.0
) -> None:
    """Ingest the records with ``t0 <= t < t1`` in batches of ``step_s`` seconds."""
    t = t0
    t1 = min(t1, max((r["t"] for r in records), default=t0) + step_s)
    while t < t1:
        batch = [r for r in records if t <= r["t"] < min(t + step_s, t1)]
        if batch:
            post_records(client, batch, f"{SCENARIO}-{t:.3f}-{min(t + step_s, t1):.3f}")
        t += step_s


@dataclass
class PageRecord:
    """What a page did: console errors, requests, WebSocket URLs."""

    errors: list[str] = field(default_factory=list)
    requests: list[str] = field(default_factory=list)
    blocked: list[str] = field(default_factory=list)
    websockets: list[str] = field(default_factory=list)

    def off_loopback(self) -> list[str]:
        out = []
        for url in [*self.requests, *self.websockets]:
            parts = urlsplit(url)
            if parts.scheme in ("blob", "data"):
                continue
            if parts.hostname not in LOOPBACK:
                out.append(url)
        return out + self.blocked


def open_console(pg: Any, server: Server, timeout_ms: int = 60_000) -> None:
    """Load the console with the token in the URL and wait until it has started."""
    pg.goto(f"{server.url}/?token={TOKEN}")
    pg.wait_for_selector("body[data-ready='1']", timeout=timeout_ms)
    pg.wait_for_selector("#conn[data-state='live']", timeout=timeout_ms)
