"""Group commit: batches that arrive together share one transaction and one WAL sync.

Batches that arrive while the pipeline's lock is held wait together; the next one to get
the lock commits all of them in one transaction and processes them as one, in arrival
order - each keeps its own batch row, acknowledgement and ``ingest`` message. If the
transaction fails, nothing of it is committed; the pipeline then commits each batch of the
group on its own, so only the batch that fails is refused (one client's bad batch never
fails another's).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from demtrack.core.tracking.types import Detection

from ..store.backend import StoreBackend
from ..store.batches import BatchMaker

__all__ = ["Ack", "GroupCommit", "Request", "commit_group"]

#: An ingested batch's acknowledgement and its newest detection time (None: none).
Ack = tuple[dict[str, Any], float | None]


@dataclass(eq=False)
class Request:
    """One ingest call waiting for its group's commit."""

    #: Detection records, or (a pose batch) the :class:`~.pose_values.ParsedPoses`.
    records: Any
    batch_key: str | None
    ack: dict[str, Any] | None = None
    error: BaseException | None = None
    #: None: a detection batch; a sensor id: a pose batch of that sensor.
    sensor: str | None = None
    #: Pose samples the batch stored, per sensor (filled when it is made).
    samples: dict[str, list[Any]] | None = None


class GroupCommit:
    """The waiting requests and the lock that serialises groups.

    Attributes
    ----------
    lock : threading.Lock
        Held while a group is committed and processed.
    waiting : list of Request
        Requests not yet taken by a group.
    """

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self._waiting_lock = threading.Lock()
        self.waiting: list[Request] = []

    def submit(
        self,
        records: Any,
        batch_key: str | None,
        run: Callable[[list[Request]], None],
        sensor: str | None = None,
    ) -> dict[str, Any]:
        """Queue one batch; under the lock, ``run`` the group it is part of; its ack.

        ``sensor``: the batch holds that sensor's poses (detections when None). Raises
        what the group's commit raised.
        """
        req = Request(records, batch_key, sensor=sensor)
        with self._waiting_lock:
            self.waiting.append(req)
        with self.lock:
            if req.ack is None and req.error is None:
                with self._waiting_lock:
                    group, self.waiting = self.waiting, []
                run(group)
        if req.error is not None:
            raise req.error
        if req.ack is None:
            raise RuntimeError("internal: an ingest request was neither acknowledged nor failed")
        return req.ack


def commit_group(
    store: StoreBackend,
    group: list[Request],
    make: Callable[[Request], tuple[Any, ...]],
) -> tuple[list[tuple[int, Detection]], list[Ack]] | None:
    """Commit ``group``'s batches in one transaction; what to process, or None if it failed.

    ``make(request)``: the batch's accepted detections and report (and, optionally, its
    pose rows: :data:`~demtrack.server.store.batches.BatchMaker`), called inside the
    transaction in order (so it may depend on the batches before it). Every request gets
    its ``ack`` (or, on failure, the ``error``). Returns the new detections with their ids
    and the acknowledgements of the batches that were not duplicates.
    """
    made: dict[int, tuple[Any, ...]] = {}

    def maker(k: int, req: Request) -> BatchMaker:
        def run() -> tuple[Any, ...]:
            made[k] = make(req)
            return made[k]

        return run

    try:
        stored = store.insert_batches(
            [(maker(k, req), req.batch_key) for k, req in enumerate(group)]
        )
    except BaseException as exc:  # nothing committed: every batch of the group fails
        for req in group:
            req.error = exc
        return None
    pending: list[tuple[int, Detection]] = []
    acks: list[Ack] = []
    for k, (req, sb) in enumerate(zip(group, stored, strict=True)):
        req.ack = {
            **sb.report,
            "batch_id": sb.batch_id,
            "detection_ids": list(sb.detection_ids),
            "duplicate": sb.duplicate,
        }
        if sb.duplicate:
            continue
        dets: list[Detection] = list(made[k][0])
        pending += zip(sb.detection_ids, dets, strict=True)
        acks.append((req.ack, max((d.t_s for d in dets), default=None)))
    return pending, acks
