"""Dynamic block claims (core.raycast._block_claims): every block is done once, by some thread."""

from __future__ import annotations

import numba
import numpy as np
import pytest
from numba import njit, prange

from demtrack.core.raycast._block_claims import BLOCKS_PER_CLAIM, new_claims, next_block


@njit(parallel=True, cache=True)
def _visit(nblocks, nthreads, slow_thread):
    """Each block's visits and the thread that made the last; one thread is slowed."""
    visits = np.zeros(nblocks, np.int64)
    by = np.full(nblocks, -1, np.int64)
    claims = new_claims()
    for th in prange(nthreads):
        blk, stop = -1, 0
        while True:
            blk, stop = next_block(claims, blk, stop, nblocks)
            if blk >= nblocks:
                break
            visits[blk] += 1
            by[blk] = th
            if th == slow_thread:  # busy work, so the other thread should take more
                acc = 0.0
                for k in range(20000):
                    acc += np.sqrt(k + blk)
                visits[blk] += int(acc < 0)
    return visits, by


@pytest.mark.parametrize("nblocks", [0, 1, BLOCKS_PER_CLAIM - 1, BLOCKS_PER_CLAIM, 9, 1000])
@pytest.mark.parametrize("nthreads", [1, 2, 5])
def test_every_block_is_claimed_exactly_once(nblocks, nthreads):
    visits, by = _visit(nblocks, nthreads, -1)
    np.testing.assert_array_equal(visits, np.ones(nblocks, np.int64))
    assert np.all((by >= 0) & (by < nthreads))
    # Claims are runs of BLOCKS_PER_CLAIM consecutive blocks, each done by one thread.
    for c0 in range(0, nblocks, BLOCKS_PER_CLAIM):
        assert len(set(by[c0 : c0 + BLOCKS_PER_CLAIM].tolist())) == 1


def test_a_slowed_thread_leaves_its_share_to_the_others():
    """With a static split the slow thread would do half the blocks; here it does few.

    The two threads are interleaved by hand (the fast one takes ten steps for each of
    the slow one's), so the test does not depend on how the OS schedules real threads:
    on a loaded machine a real "fast" thread may not run at all for a while.
    """
    nblocks = 2000
    claims = new_claims()
    state = [(-1, 0), (-1, 0)]  # (block, stop) of the slow thread 0 and the fast thread 1
    done: list[list[int]] = [[], []]
    finished = [False, False]
    while not all(finished):
        for th, steps in ((0, 1), (1, 10)):
            for _ in range(steps):
                if finished[th]:
                    break
                blk, stop = next_block(claims, *state[th], nblocks)
                state[th] = (blk, stop)
                if blk >= nblocks:
                    finished[th] = True
                else:
                    done[th].append(int(blk))
    visits = np.bincount(np.array(done[0] + done[1], np.int64), minlength=nblocks)
    np.testing.assert_array_equal(visits, np.ones(nblocks, np.int64))
    assert len(done[0]) < 0.4 * nblocks
    assert len(done[0]) > 0


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs two threads")
def test_real_threads_with_one_slowed_share_every_block_once():
    """Real numba threads, one slowed: every block still done exactly once."""
    visits, by = _visit(2000, 2, 0)
    np.testing.assert_array_equal(visits, np.ones(2000, np.int64))
    assert np.all((by >= 0) & (by < 2))
