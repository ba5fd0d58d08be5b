"""The running server's state: what the routers and services share, built in the lifespan.

The routers reach it through :data:`demtrack.server.api.deps.StateDep`.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Any

from demtrack.core.raycast.cast import RayCaster
from demtrack.core.site.folder import Site

from .hub import Hub
from .ingest.pipeline import Pipeline
from .ingest.poses import PoseIngest
from .settings import Settings
from .store.backend import StoreBackend

__all__ = ["ConsoleState"]


@dataclass(eq=False)
class ConsoleState:
    """Everything the routers share (built in the app's lifespan)."""

    settings: Settings
    site: Site
    store: StoreBackend
    hub: Hub
    pipeline: Pipeline
    caster: RayCaster
    cache: dict[str, Any] = field(default_factory=dict)
    cache_lock: threading.RLock = field(default_factory=threading.RLock)
    #: Pose telemetry in (``accept``) and each sensor's current pose and footprint.
    poses: PoseIngest = field(default=None)  # type: ignore[assignment]  # made below

    def __post_init__(self) -> None:
        if self.poses is None:
            self.poses = PoseIngest(self.pipeline, self.caster)

    def cached(self, key: str, make: Any) -> Any:
        """``make()`` once per key (renders, footprints)."""
        with self.cache_lock:
            if key not in self.cache:
                self.cache[key] = make()
            return self.cache[key]
