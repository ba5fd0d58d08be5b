"""What the live replay needs from whoever supplies its scenarios.

The server generates no scenarios itself: the caller of
:func:`~demtrack.server.app.create_app` (``demtrack serve``, ``demtrack demo``, a test, a
benchmark) hands it a :class:`ScenarioSource`, and the replay asks that source for the
scenarios named in ``Settings.replay``. ``demtrack.samplesite.replay_source`` has the
sample site's.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Protocol

from demtrack.core.site.folder import Site
from demtrack.core.tracking.types import Detection, TruthPath

__all__ = ["ReplayScenario", "ScenarioSource"]


class ReplayScenario(Protocol):
    """A scenario the replay plays: detections in time order and the true paths."""

    @property
    def detections(self) -> Sequence[Detection]:
        """Detections in time order, then sensor (times from 0, s)."""
        ...

    @property
    def truths(self) -> Sequence[TruthPath]:
        """The targets' true paths (site frame, m), for spacing concurrent scenarios."""
        ...

    # A scenario of moving cameras may also have ``poses``: sensor id -> PoseSeries (the
    # heads' telemetry, times from 0). Not part of the protocol: the replay reads it with
    # ``getattr(scenario, "poses", None)``, so a scenario without one plays as before.


class ScenarioSource(Protocol):
    """Names and makes the scenarios a replay may play."""

    @property
    def names(self) -> Sequence[str]:
        """Every scenario name :meth:`make` accepts."""
        ...

    @property
    def rate_hz(self) -> float:
        """The cameras' frame rate (Hz) of a scenario made without one."""
        ...

    def make(
        self, site: Site, name: str, *, seed: int, rate_hz: float | None = None
    ) -> ReplayScenario:
        """Scenario ``name`` on ``site`` with noise seed ``seed`` at ``rate_hz`` (or its own)."""
        ...
