"""The running server's state and its dependency alias."""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from typing import Annotated, Any

from fastapi import Depends, Request

from demtrack.core.raycast.cast import RayCaster
from demtrack.core.site.folder import Site

from .db import Store
from .hub import Hub
from .pipeline import Pipeline
from .settings import Settings

__all__ = ["ConsoleState", "StateDep", "get_state"]


@dataclass(eq=False)
class ConsoleState:
    """Everything the routers share (built in the app's lifespan)."""

    settings: Settings
    site: Site
    store: Store
    hub: Hub
    pipeline: Pipeline
    caster: RayCaster
    cache: dict[str, Any] = field(default_factory=dict)
    cache_lock: threading.RLock = field(default_factory=threading.RLock)

    def cached(self, key: str, make: Any) -> Any:
        """``make()`` once per key (renders, footprints)."""
        with self.cache_lock:
            if key not in self.cache:
                self.cache[key] = make()
            return self.cache[key]


def get_state(request: Request) -> ConsoleState:
    """The app's :class:`ConsoleState`."""
    return request.app.state.console


StateDep = Annotated[ConsoleState, Depends(get_state)]
