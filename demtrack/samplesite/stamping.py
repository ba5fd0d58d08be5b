"""Real times for generated scenarios: their time 0 moved to a chosen UTC instant.

A scenario is generated on its own clock (``t = 0`` at its start). Stamped, every
detection, every truth sample and every pose telemetry sample is moved by the same shift,
so ``t_s`` are UNIX seconds UTC and a detection file or a replay carries real times
(``demtrack scenario --start``, ``demtrack serve --demo --start``). The shift is exact
in the sense that matters: float64 holds a 2026 UNIX time to 0.24 us.
"""

from __future__ import annotations

import time
from dataclasses import replace

from demtrack.core.camera.pose_series import PoseSeries
from demtrack.core.io.times import parse_iso_time
from demtrack.core.tracking.types import Detection, TruthPath

from .scenarios import Scenario

__all__ = ["parse_start", "stamp_scenario"]


def parse_start(text: str | None, option: str = "--start", now_s: float | None = None) -> float:
    """UNIX seconds of a start option: ``now`` (the default) or ISO 8601 with a zone.

    ``now`` is rounded down to a whole second, so the stamped times read cleanly.
    :class:`~demtrack.core.errors.TimeFormatError` (one line naming ``option``) otherwise.
    """
    if text is None or text.strip().lower() == "now":
        return float(int(time.time() if now_s is None else now_s))
    return parse_iso_time(text, option)


def stamp_scenario(sc: Scenario, t0_s: float) -> Scenario:
    """``sc`` with its time 0 at UNIX second ``t0_s``: detections, truths, poses alike."""
    shift = float(t0_s)
    dets = [
        Detection._trusted(d.t_s + shift, d.sensor, d.bbox, d.cls, d.score, d.local_id)
        for d in sc.detections
    ]
    truths = [TruthPath(tr.target_id, tr.cls, tr.t_s + shift, tr.p_enu) for tr in sc.truths]
    poses = {
        sid: PoseSeries.from_samples([replace(p, t_s=p.t_s + shift) for p in series.samples()])
        for sid, series in sc.poses.items()
    }
    return replace(sc, detections=dets, truths=truths, poses=poses)
