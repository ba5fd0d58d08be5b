"""Durable ingest: batches, their accepted detections and poses, several per transaction.

:func:`insert_batch_rows` runs inside the store's write transaction (committed with
``synchronous=FULL``: when it returns to the caller the batch is on disk). A batch whose
client key was seen before inserts nothing and gives its first report back.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from .codec import dumps_json, loads_json
from .poses import insert_pose_rows

__all__ = ["BatchMaker", "StoredBatch", "insert_batch_rows"]

#: ``make()`` -> the batch's accepted detections and report, and optionally its pose rows
#: (:data:`.poses.PoseRow`, a third element), called inside the transaction.
BatchMaker = Callable[[], tuple[Any, ...]]


@dataclass(frozen=True)
class StoredBatch:
    """A committed ingest batch.

    Attributes
    ----------
    batch_id : int
    detection_ids : tuple of int
        Ids of its accepted detections, in record order.
    report : dict
        The acknowledgement sent for it (returned again for a repeated ``batch_key``).
    duplicate : bool
        The key had been seen: nothing was inserted this time.
    """

    batch_id: int
    detection_ids: tuple[int, ...]
    report: dict[str, Any]
    duplicate: bool = False


def insert_batch_rows(
    c: Any, batches: Sequence[tuple[BatchMaker, str | None]]
) -> list[StoredBatch]:
    """Insert ``batches`` (``(make, batch_key)`` each, in order) on ``c``, in its transaction.

    See :meth:`demtrack.server.store.database.Store.insert_batches`.
    """
    out = []
    for make, batch_key in batches:
        if batch_key is not None:
            row = c.execute(
                "SELECT id, report FROM batches WHERE batch_key = ?", (batch_key,)
            ).fetchone()
            if row is not None:
                known = tuple(
                    int(r[0])
                    for r in c.execute(
                        "SELECT id FROM detections WHERE batch_id = ? ORDER BY id",
                        (row[0],),
                    )
                )
                out.append(StoredBatch(row[0], known, loads_json(row[1]), duplicate=True))
                continue
        made = make()
        detections, report = made[0], made[1]
        poses = made[2] if len(made) > 2 else ()
        # One statement gives the batch's id and the detections' highest id. The id is
        # the next one, given explicitly (what SQLite picks itself), so both databases
        # number batches alike, even after a rolled-back transaction.
        ((batch_id, last_id),) = c.execute(
            "INSERT INTO batches (id, batch_key, n_records, n_accepted, report)"
            " VALUES ((SELECT COALESCE(MAX(id), 0) + 1 FROM batches),?,?,?,?)"
            " RETURNING id, (SELECT MAX(id) FROM detections)",
            (batch_key, report["n_records"], report["accepted"], dumps_json(report)),
        ).fetchall()
        # Ids are given explicitly (the next ones, in record order: the write lock
        # and BEGIN IMMEDIATE make this the only writer) so one executemany inserts
        # them.
        first = 1 if last_id is None else int(last_id) + 1
        ids = tuple(range(first, first + len(detections)))
        c.executemany(
            "INSERT INTO detections (id, batch_id, t_s, sensor, u_min, v_min, u_max,"
            " v_max, cls, score, local_id) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
            [
                (i, batch_id, d.t_s, d.sensor, *d.bbox, d.cls, d.score, d.local_id)
                for i, d in zip(ids, detections, strict=True)
            ],
        )
        if poses:
            insert_pose_rows(c, batch_id, poses)
        out.append(StoredBatch(batch_id, ids, report))
    return out
