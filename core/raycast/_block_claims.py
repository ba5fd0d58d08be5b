"""Blocks of work handed out to threads as they ask (dynamic scheduling inside numba).

numba's ``prange`` splits its range into one fixed share per thread. When one thread is
slowed (another process on its core, a noisy neighbour on a shared machine) the others
finish their shares and wait. Kernels that loop ``for th in prange(nthreads)`` and claim
their blocks with :func:`next_block` instead keep every thread busy until the work runs
out: a thread takes the next unclaimed blocks, in order, so threads still work side by
side on neighbouring blocks.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.extending import intrinsic

__all__ = ["BLOCKS_PER_CLAIM", "next_block", "new_claims"]

#: Blocks a thread takes per claim. Every claim moves the counter's cache line between
#: cores; in stretches when this shared machine's cores are far apart one move took about
#: a microsecond, and one-block claims (64 rays each) then cost more than they saved. Eight
#: blocks of camera rays are about 50 us of work: few claims, and a short tail.
BLOCKS_PER_CLAIM = 8

#: Length of the claims array; the counter sits in the middle, a cache line or more from
#: either end, so no other allocation shares its line (threads write it on every claim).
_CLAIMS_LEN = 32
_CLAIM_SLOT = 16


@intrinsic
def _fetch_add(typingctx, arr, idx, val):  # noqa: ANN001, ANN202 - numba intrinsic
    """``arr[idx] += val`` as one atomic operation; returns the value before."""
    if not (isinstance(arr, types.Array) and arr.dtype == types.int64):
        return None
    sig = types.int64(arr, types.intp, types.int64)

    def codegen(context, builder, signature, args):  # noqa: ANN001, ANN202
        a, i, v = args
        ary = context.make_array(signature.args[0])(context, builder, a)
        ptr = builder.gep(ary.data, [i])
        return builder.atomic_rmw("add", ptr, v, "monotonic")

    return sig, codegen


@njit(cache=True)
def new_claims():  # pragma: no cover - numba
    """A fresh counter of claimed blocks (allocate it before the ``prange``)."""
    return np.zeros(_CLAIMS_LEN, np.int64)


@njit(cache=True, inline="always")
def next_block(claims, blk, stop, nblocks):  # pragma: no cover - numba
    """The calling thread's next block after ``blk``, and the end of its current claim.

    Start a thread with ``blk, stop = -1, 0``; once the answer's block is ``>= nblocks``
    the work is done. Within a claim the blocks follow on; past it, the next unclaimed
    ``BLOCKS_PER_CLAIM`` blocks are claimed.
    """
    blk += 1
    if blk >= stop:
        blk = _fetch_add(claims, _CLAIM_SLOT, BLOCKS_PER_CLAIM)
        stop = min(blk + BLOCKS_PER_CLAIM, nblocks)
    return blk, stop
