"""The sample site's scenarios as a scenario source for the console's live replay.

``demtrack serve``, ``demtrack demo``, the benchmarks and the tests hand
:data:`SAMPLE_SCENARIOS` to :func:`demtrack.server.app.create_app` (or to the replay
functions of :mod:`demtrack.server.replay`); the server itself never imports the
generator. It fits :class:`demtrack.server.scenario_source.ScenarioSource` by shape.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

from demtrack.core.site.folder import Site

from .activity_scenarios import ACTIVITY_CASES, DEFAULT_ACTIVITY_PARAMS, make_activity_scenario
from .scenarios import SCENARIOS, Scenario, ScenarioParams, make_scenario

__all__ = ["SAMPLE_SCENARIOS", "SampleScenarios"]


@dataclass(frozen=True)
class SampleScenarios:
    """The generated sample site's scenarios, default noise.

    The trajectory scenarios (:data:`~.scenarios.SCENARIOS`) and the activity cases
    (:data:`~.activity_scenarios.ACTIVITY_CASES`: loitering, rendezvous, convoys, ...), so a
    live replay can show every activity detector. ``active-handoff`` comes with its heads'
    pose telemetry (:attr:`~.scene_render.Scenario.poses`), which the replay posts beside
    the detections; the sample site's sensors carry its latency (``pose_latency_s``).
    """

    @property
    def names(self) -> tuple[str, ...]:
        """The scenario names: the trajectory scenarios, then the activity cases (sorted)."""
        return (*sorted(SCENARIOS), *sorted(ACTIVITY_CASES))

    @property
    def rate_hz(self) -> float:
        """The scenarios' own frame rate (Hz)."""
        return ScenarioParams().rate_hz

    def make(self, site: Site, name: str, *, seed: int, rate_hz: float | None = None) -> Scenario:
        """:func:`~.scenarios.make_scenario` with default noise, seed ``seed``, at ``rate_hz``.

        Raises
        ------
        SiteError
            Unknown scenario, or a site that is not a generated sample site.
        """
        if name in ACTIVITY_CASES:
            params = replace(DEFAULT_ACTIVITY_PARAMS, seed=seed)
            if rate_hz is not None:
                params = replace(params, rate_hz=rate_hz)
            return make_activity_scenario(site, name, params).scenario
        params = ScenarioParams() if rate_hz is None else ScenarioParams(rate_hz=rate_hz)
        return make_scenario(site, name, replace(params, seed=seed))


#: The one instance callers hand over.
SAMPLE_SCENARIOS = SampleScenarios()
