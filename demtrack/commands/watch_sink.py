"""Where ``demtrack watch`` sends what it finds: a console server, or a JSON Lines file.

:class:`ServerSink` posts each batch (detections to ``POST /api/detections``, KLV poses
to ``POST /api/sensors/{id}/poses``) from a background thread, in order, with a
deterministic ``batch_key``. A batch that fails to reach the server (connection refused,
reset, a 5xx, 503 while the server starts) is retried with exponential back-off (0.25 s
doubling to 8 s) until it is acknowledged, so a server restart loses nothing; the server
stores a batch key once, so a batch resent after its acknowledgement was lost is not
stored twice. A 4xx other than 408/429 is a mistake (a bad token, a bad record): one line
and stop. :class:`JsonlSink` appends records to a file that ``demtrack track`` reads,
flushed per batch.
"""

from __future__ import annotations

import json
import queue
import threading
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from demtrack.core.errors import DemtrackError
from demtrack.core.tracking.types import Detection

__all__ = ["Batch", "JsonlSink", "ServerSink", "WatchError", "detection_record"]


class WatchError(DemtrackError, RuntimeError):
    """The server refused a batch (bad token, bad request) or could not be reached in time."""


def detection_record(d: Detection) -> dict[str, Any]:
    """The detection JSON Lines / HTTP record of one detection."""
    rec: dict[str, Any] = {"t": d.t_s, "sensor": d.sensor, "bbox": list(d.bbox), "class": d.cls}
    if d.score is not None:
        rec["score"] = d.score
    if d.local_id is not None:
        rec["local_id"] = d.local_id
    return rec


@dataclass
class Batch:
    """One batch: its key, detection records and pose records (either may be empty)."""

    key: str
    detections: list[dict[str, Any]] = field(default_factory=list)
    poses: list[dict[str, Any]] = field(default_factory=list)


class JsonlSink:
    """Detections as JSON Lines (poses, where any, to ``<name>.poses.jsonl`` beside it)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self._fh = self.path.open("w", encoding="utf-8")
        self._poses = None
        self.n_detections = 0
        self.n_poses = 0

    def put(self, batch: Batch) -> None:
        """Write a batch and flush."""
        for rec in batch.detections:
            self._fh.write(json.dumps(rec, allow_nan=False) + "\n")
        self._fh.flush()
        self.n_detections += len(batch.detections)
        if batch.poses:
            if self._poses is None:
                self._poses = self.path.with_suffix(".poses.jsonl").open("w", encoding="utf-8")
            for rec in batch.poses:
                self._poses.write(json.dumps(rec, allow_nan=False) + "\n")
            self._poses.flush()
            self.n_poses += len(batch.poses)

    def close(self) -> None:
        """Close the files."""
        self._fh.close()
        if self._poses is not None:
            self._poses.close()


class ServerSink:
    """Post batches to a console server from a background thread (see the module docstring).

    Parameters
    ----------
    url : str
        The server's base URL (``http://host:port``).
    sensor : str
        Sensor id (for the poses endpoint).
    token : str, optional
        The operator token (``Authorization: Bearer``).
    queue_size : int
        Batches waiting before :meth:`put` blocks (back-pressure on the decoder).
    give_up_s : float
        A batch not acknowledged after this long of retrying ends the watch.
    log : callable
        Where one-line notes go (stderr).
    """

    def __init__(
        self,
        url: str,
        sensor: str,
        token: str | None = None,
        *,
        queue_size: int = 64,
        give_up_s: float = 600.0,
        timeout_s: float = 10.0,
        log=None,
    ) -> None:
        self.url = url.rstrip("/")
        self.sensor = sensor
        self.token = token
        self.give_up_s = float(give_up_s)
        self.timeout_s = float(timeout_s)
        self.log = log or (lambda msg: None)
        self._queue: queue.Queue[Batch | None] = queue.Queue(maxsize=queue_size)
        self.error: BaseException | None = None
        self.n_detections = 0
        self.n_poses = 0
        self.n_retries = 0
        self.acked: list[str] = []
        self._poses_missing = False
        self._thread = threading.Thread(target=self._run, name="watch-sink", daemon=True)
        self._thread.start()

    def put(self, batch: Batch) -> None:
        """Queue a batch (blocks while the queue is full); raises the sender's error."""
        if self.error is not None:
            raise self.error
        while True:
            try:
                self._queue.put(batch, timeout=0.5)
                return
            except queue.Full:
                if self.error is not None:
                    raise self.error from None

    def close(self) -> None:
        """Wait until every queued batch is acknowledged; raises the sender's error."""
        if self._thread.is_alive():
            self.put_end()
        self._thread.join()
        if self.error is not None:
            raise self.error

    def put_end(self) -> None:
        """Queue the end marker (waits while the sender is alive and the queue full)."""
        while self._thread.is_alive():
            try:
                self._queue.put(None, timeout=0.5)
                return
            except queue.Full:
                continue

    def _run(self) -> None:
        while True:
            batch = self._queue.get()
            if batch is None:
                return
            try:
                if batch.detections:
                    body = {"batch_key": batch.key, "detections": batch.detections}
                    self._post("/api/detections", body)
                    self.n_detections += len(batch.detections)
                if batch.poses and not self._poses_missing:
                    body = {"batch_key": batch.key + ":poses", "poses": batch.poses}
                    if self._post(f"/api/sensors/{self.sensor}/poses", body, optional=True):
                        self.n_poses += len(batch.poses)
                self.acked.append(batch.key)
            except BaseException as exc:  # handed to the main thread
                self.error = exc
                return

    def _post(self, path: str, body: dict[str, Any], optional: bool = False) -> bool:
        data = json.dumps(body, allow_nan=False).encode()
        headers = {"Content-Type": "application/json"}
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        delay, started, noted = 0.25, time.monotonic(), False
        while True:
            req = urllib.request.Request(self.url + path, data=data, headers=headers)
            try:
                with urllib.request.urlopen(req, timeout=self.timeout_s) as resp:
                    resp.read()
                if noted:
                    self.log(f"server {self.url} is back; batch {body['batch_key']} sent")
                return True
            except urllib.error.HTTPError as exc:
                detail = exc.read().decode(errors="replace").strip()[:200]
                if exc.code == 404 and optional:
                    self._poses_missing = True
                    self.log(f"server has no {path}; KLV poses are not sent")
                    return False
                if 400 <= exc.code < 500 and exc.code not in (408, 429):
                    raise WatchError(f"server refused {path} ({exc.code}): {detail}") from None
                why = f"HTTP {exc.code}"
            except (urllib.error.URLError, OSError) as exc:
                why = str(getattr(exc, "reason", exc))
            if time.monotonic() - started > self.give_up_s:
                raise WatchError(
                    f"server {self.url} unreachable for {self.give_up_s:.0f} s ({why})"
                )
            if not noted:
                self.log(f"server {self.url} unreachable ({why}); retrying with back-off")
                noted = True
            self.n_retries += 1
            time.sleep(delay)
            delay = min(delay * 2, 8.0)
