"""Multi-target, multi-sensor tracking of ray-terrain fixes (after Stone Soup's design).

Entry points: :func:`run_tracker` (batch), :func:`build_tracker` (online
:class:`Tracker`), :data:`METHODS`; values in :mod:`.types`; metrics in :mod:`.metrics`
and :mod:`.ospa`.
"""

from __future__ import annotations

from .config import ClassParams, TrackerConfig
from .methods import METHODS, build_tracker, run_tracker
from .metrics import TrackingMetrics, evaluate
from .roads import RoadGraph
from .tracker import Tracker, TrackerComponents
from .types import Detection, Fix, Track, TrackPoint, TruthPath

__all__ = [
    "METHODS",
    "ClassParams",
    "Detection",
    "Fix",
    "RoadGraph",
    "Track",
    "TrackPoint",
    "Tracker",
    "TrackerComponents",
    "TrackerConfig",
    "TrackingMetrics",
    "TruthPath",
    "build_tracker",
    "evaluate",
    "run_tracker",
]
