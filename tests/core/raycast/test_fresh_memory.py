"""Cast outputs allocated without numpy's huge-page advice, and the switch restored."""

from __future__ import annotations

import threading

import numpy as np
import pytest

from demtrack.core.raycast import fresh_memory
from demtrack.core.raycast.fresh_memory import without_huge_page_advice


@pytest.fixture
def switch():
    fn = fresh_memory._SET_ADVICE
    assert fn is not None, "numpy's _set_madvise_hugepage switch is gone: the advice stays on"
    before = fn(True)
    yield fn
    fn(before)


def _state(fn) -> bool:
    now = fn(True)
    fn(now)
    return now


@pytest.mark.parametrize("initial", [True, False])
def test_the_switch_is_off_inside_and_restored_after(switch, initial):
    switch(initial)
    with without_huge_page_advice():
        assert _state(switch) is False
        a = np.empty(1 << 20)  # 8 MB: would be advised
    assert _state(switch) is initial
    a[:] = 1.0
    assert a.sum() == 1 << 20


def test_restored_after_an_error_inside(switch):
    with pytest.raises(RuntimeError), without_huge_page_advice():
        raise RuntimeError("boom")
    assert _state(switch) is True


def test_concurrent_users_leave_it_as_it_was(switch):
    def work():
        for _ in range(200):
            with without_huge_page_advice():
                np.empty(1 << 20)

    threads = [threading.Thread(target=work) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert _state(switch) is True
