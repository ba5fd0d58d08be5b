"""Large result arrays allocated without numpy's transparent-huge-page advice.

numpy asks the kernel (``madvise(MADV_HUGEPAGE)``) to back every array of 4 MB or more
with huge pages. Where transparent huge pages are ``madvise``-only with ``defrag`` on
``madvise`` (Debian's default), the first touch of such memory may compact memory to find
a free 2 MB page: writing 42 MB of fresh cast output took 49-56 ms with the advice and
17 ms without on the development machine (docs/benchmarks.md). A cast's outputs are
written once and handed to the caller, so they are allocated without it.
"""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

import numpy as np

__all__ = ["without_huge_page_advice"]

_LOCK = threading.Lock()


def _setter():  # noqa: ANN202 - numpy's private switch, absent in some versions
    for mod in ("_core", "core"):
        ma = getattr(getattr(np, mod, None), "multiarray", None)
        fn = getattr(ma, "_set_madvise_hugepage", None)
        if fn is not None:
            return fn
    return None


_SET_ADVICE = _setter()


@contextlib.contextmanager
def without_huge_page_advice() -> Iterator[None]:
    """Arrays allocated inside get no huge-page advice (numpy's switch, restored after).

    The switch is process-wide: the lock keeps concurrent users from restoring it out of
    order; another thread allocating meanwhile only loses a hint. Allocation only: the
    advice is given when numpy allocates, so fill the arrays after leaving.
    """
    if _SET_ADVICE is None:
        yield
        return
    with _LOCK:
        before = _SET_ADVICE(False)
        try:
            yield
        finally:
            _SET_ADVICE(before)
