"""Names and defaults the parsers show, kept free of heavy imports.

``demtrack --help`` and every parser are built from this module alone, so building them
loads neither numba, scipy, rasterio, shapely, pyproj nor the server. Each constant copies
a value owned by a heavy module (named beside it); ``tests/cli/test_cli_imports.py`` fails
when a copy goes stale.
"""

from __future__ import annotations

__all__ = [
    "ACTIVE_LATENCY_S",
    "ACTIVE_SCENARIO_NAMES",
    "ACTIVITY_CASE_NAMES",
    "ACTIVITY_SEED",
    "DEFAULT_FREE",
    "DEFAULT_METHOD",
    "FREE_PARAMETERS",
    "GCP_FORMATS",
    "GCP_LOSSES",
    "GEOLOCATE_RULES",
    "MANIFEST",
    "SCENARIO_DEFAULTS",
    "REPLAY_NAMES",
    "SCENARIO_NAMES",
    "TRACKING_METHODS",
]

#: ``demtrack.core.tracking.METHODS``, in its order.
TRACKING_METHODS: tuple[str, ...] = (
    "raw-first",
    "last-hit",
    "kalman",
    "multi-hypothesis",
    "multi-hypothesis-road",
    "road",
)
#: Tracking method used by ``track``, ``activity``, ``gaps`` and ``evaluate-activity``.
DEFAULT_METHOD = "multi-hypothesis-road"

#: ``demtrack.core.site.folder.MANIFEST``: a folder holding this file is a site.
MANIFEST = "site.json"

#: ``demtrack.core.geolocation.geolocate.RULES``.
GEOLOCATE_RULES: tuple[str, ...] = ("first", "last", "all", "road")

#: ``sorted(demtrack.samplesite.scenarios.SCENARIOS)``.
SCENARIO_NAMES: tuple[str, ...] = (
    "active-handoff",
    "passing-vehicles",
    "pedestrians",
    "vehicle-run",
)
#: ``sorted(demtrack.samplesite.scenarios.ACTIVE_SCENARIOS)``.
ACTIVE_SCENARIO_NAMES: tuple[str, ...] = ("active-handoff",)
#: ``demtrack.samplesite.active_scenario.ActiveParams().latency_s``.
ACTIVE_LATENCY_S = 0.08

#: Defaults of ``demtrack.samplesite.scenarios.ScenarioParams`` the options expose.
SCENARIO_DEFAULTS: dict[str, float] = {
    "noise_px": 1.0,
    "p_miss": 0.05,
    "false_alarm_rate": 0.02,
    "seed": 0,
}

#: ``demtrack.samplesite.activity_scenarios.ACTIVITY_CASES``, in its order.
ACTIVITY_CASE_NAMES: tuple[str, ...] = (
    "loitering",
    "rendezvous",
    "passing",
    "convoy",
    "convoy-uneven",
    "convoy-short",
)
#: What ``--replay`` takes: ``demtrack.samplesite.replay_source.SAMPLE_SCENARIOS.names``.
REPLAY_NAMES: tuple[str, ...] = (*SCENARIO_NAMES, *sorted(ACTIVITY_CASE_NAMES))
#: ``demtrack.samplesite.activity_scenarios.DEFAULT_ACTIVITY_PARAMS.seed``.
ACTIVITY_SEED = 0

#: ``demtrack.core.camera.gcp_calibration.FREE_PARAMETERS`` and ``DEFAULT_FREE``.
FREE_PARAMETERS: tuple[str, ...] = (
    "yaw", "tilt", "roll", "f", "fx", "fy", "cx", "cy",
    "k1", "k2", "k3", "p1", "p2", "x", "y", "z",
)  # fmt: skip
#: ``demtrack.core.camera.gcp_calibration.LOSSES``.
GCP_LOSSES: tuple[str, ...] = ("linear", "soft_l1", "huber", "cauchy", "arctan")
#: ``demtrack.core.camera.gcp_convert.GCP_FORMATS``.
GCP_FORMATS: tuple[str, ...] = ("csv", "imgraft")
DEFAULT_FREE: tuple[str, ...] = ("yaw", "tilt", "roll")
