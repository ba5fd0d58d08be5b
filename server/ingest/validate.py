"""Detection records checked with the detection-file rules, time order across batches.

The rules are those of :mod:`demtrack.core.io.detections`. Time order is checked across
batches too: one valid seed record per sensor at its latest stored time goes first, so
the reader's own ``time_backwards`` rule sees it. Only the batch's own sensors need one
(the reader keeps its time order per sensor, and a seed is never skipped), so a camera's
small batch checks no others' seeds.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

from demtrack.core.io.detections import read_detection_records
from demtrack.core.tracking.types import Detection

__all__ = ["MAX_ISSUES", "relative_to", "validate_records"]

#: The most issues an acknowledgement lists.
MAX_ISSUES = 20


def relative_to(records: Sequence[Any], epoch_s: float | None) -> list[Any]:
    """``records`` with each numeric ``t`` moved to ``epoch_s + t`` (UNIX seconds).

    A batch that declares an epoch: its numbers are seconds after it. Anything else
    (an ISO ``time``, a record the reader will refuse) passes unchanged.
    """
    if epoch_s is None:
        return list(records)
    out: list[Any] = []
    for r in records:
        t = r.get("t") if isinstance(r, dict) else None
        if isinstance(t, int | float) and not isinstance(t, bool) and abs(t) < 1e300:
            out.append({**r, "t": epoch_s + float(t)})
        else:
            out.append(r)
    return out


def validate_records(
    records: Sequence[Any],
    last_t: Mapping[str, float],
    sizes: Mapping[str, tuple[int, int]],
    poses_out: dict[str, Any] | None = None,
) -> tuple[list[Detection], dict[str, Any]]:
    """The accepted detections of ``records`` and the acknowledgement's counts.

    Parameters
    ----------
    records : sequence
        Detection records as posted (dicts, or anything the reader refuses).
    last_t : mapping of str to float
        Each sensor's latest stored detection time (s).
    sizes : mapping of str to (int, int)
        Each sensor's image ``(width_px, height_px)``.
    poses_out : dict, optional
        Filled with the inline poses of the accepted records (``pan_deg``, ``tilt_deg``,
        ``hfov_deg`` fields): sensor id -> tuple of PoseSample, in record order.
    """
    named = {
        r["sensor"] for r in records if isinstance(r, dict) and isinstance(r.get("sensor"), str)
    }
    seeds = [
        {"t": t, "sensor": s, "bbox": [0, 0, 0, 0], "class": "human"}
        for s, t in sorted(last_t.items())
        if s in named and s in sizes
    ]
    dets, report = read_detection_records(
        [*seeds, *records], sensors=sizes, max_examples=MAX_ISSUES
    )
    if poses_out is not None:
        poses_out.update(report.poses)
    n_seed = len(seeds)
    if len(dets) < n_seed or report.n_records != n_seed + len(records):
        raise RuntimeError("internal: detection seed records were not accepted")
    issues = [
        {"index": e.line - 1 - n_seed, "reason": e.reason, "message": e.message}
        for e in report.examples
    ]
    ack = {
        "n_records": len(records),
        "accepted": len(dets) - n_seed,
        "skipped": report.n_skipped,
        "counts": dict(report.counts),
        "issues": issues,
    }
    return dets[n_seed:], ack
