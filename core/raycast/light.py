"""The process-wide switch between the fast casting kernels and their light twins.

The light kernels (``core.raycast._light_kernels``) give the same answers bit for bit and
compile in well under half the time; ``core.raycast.cast`` reads the switch on every cast.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

__all__ = ["light_kernels", "light_kernels_on", "use_light_kernels"]


class _LightState:
    """Whether casts use the light kernels (``core.raycast._light_kernels``)."""

    on = False


_LIGHT = _LightState()


def use_light_kernels(enabled: bool = True) -> None:
    """Cast with the light kernels (``True``) or the fast ones (``False``, the default).

    The light kernels give the same answers bit for bit and compile in well under half the
    time; they cast on one thread (releasing the GIL), a new caster builds its min/max
    pyramid in plain numpy, and ``coherent=None`` builds no angular index
    (``coherent=True`` still does). For a process whose numba cache is cold and that
    needs answers before the fast kernels could compile (the sample-site build's renders,
    ``demtrack demo`` until its warm-up is done). Process-wide;
    :func:`demtrack.core.warm.warm_raycast` turns them off once the fast kernels are ready.
    """
    _LIGHT.on = bool(enabled)


def light_kernels_on() -> bool:
    """Whether casts use the light kernels (see :func:`use_light_kernels`)."""
    return _LIGHT.on


@contextlib.contextmanager
def light_kernels() -> Iterator[None]:
    """Cast with the light kernels inside the block; the previous choice after it."""
    before = _LIGHT.on
    _LIGHT.on = True
    try:
        yield
    finally:
        _LIGHT.on = before
