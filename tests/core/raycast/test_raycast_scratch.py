"""Pooled first-pass scratch of ``RayCaster.cast``: same answers, nothing shared, thread-safe."""

from __future__ import annotations

import contextlib
import threading
from collections.abc import Iterator

import numba
import numpy as np
import pytest
from raycast_checks import HIT_FIELDS, assert_identical_hits

from demtrack.bench.synthetic_terrain import camera_rays, incoherent_rays, synthetic_dem
from demtrack.core.raycast import scratch as rc
from demtrack.core.raycast.cast import RayCaster
from demtrack.core.raycast.hits import RayHits
from demtrack.core.raycast.light import light_kernels


@pytest.fixture(scope="module")
def dem():
    return synthetic_dem(300, 0.5, seed=3)


@pytest.fixture(scope="module")
def batches(dem) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    # Camera runs of 25k rays (above MIN_COHERENT_RUN: cast with angular indexes) and
    # incoherent rays (above MIN_ORDERED_RAYS: the ordered pyramid walk).
    return {
        "camera": camera_rays(dem, 75_000, n_cameras=3, seed=1),
        "incoherent": incoherent_rays(dem, 30_000, seed=2),
        "small": incoherent_rays(dem, 500, seed=5),
    }


@pytest.fixture
def pooled(monkeypatch) -> Iterator[None]:
    """Every cast's first pass takes the pool, however small."""
    monkeypatch.setattr(rc, "_SCRATCH_MIN_BYTES", 0)
    monkeypatch.setattr(rc, "_SCRATCH", rc._ScratchPool())
    yield


def unpooled_cast(dem, o, d, **kw) -> RayHits:
    """The answer of a fresh caster that allocates its scratch (the code before the pool)."""
    saved = rc._SCRATCH_MIN_BYTES
    rc._SCRATCH_MIN_BYTES = 1 << 62
    try:
        return RayCaster.from_dem(dem).cast(o, d, **kw)
    finally:
        rc._SCRATCH_MIN_BYTES = saved


def poison() -> None:
    """Fill the kept buffers with garbage: stale contents must not matter."""
    for buf in rc._SCRATCH._free:
        buf.view(np.int64)[:] = -1
        buf[::3] = np.nan


CASES = [
    ("camera", "all", 256),
    ("camera", "all", 3),
    ("camera", "first", 256),
    ("incoherent", "all", 256),
    ("incoherent", "first", 256),
    ("small", "all", 256),
]


@pytest.mark.parametrize("threads", [1, 2])
@pytest.mark.parametrize("light", [False, True])
def test_reused_scratch_gives_the_fresh_answers(dem, batches, pooled, threads, light):
    prev = numba.get_num_threads()
    numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
    try:
        with light_kernels() if light else contextlib.nullcontext():
            expected = {
                c: unpooled_cast(dem, *batches[c[0]], mode=c[1], max_hits=c[2]) for c in CASES
            }
            caster = RayCaster.from_dem(dem)
            for _ in range(2):
                for case in CASES + CASES[::-1]:
                    name, mode, max_hits = case
                    hits = caster.cast(*batches[name], mode=mode, max_hits=max_hits)
                    assert_identical_hits(hits, expected[case])
                    for buf in rc._SCRATCH._free:
                        for field in HIT_FIELDS:
                            assert not np.shares_memory(getattr(hits, field), buf)
                    poison()
            assert rc._SCRATCH._free  # the pool was used
    finally:
        numba.set_num_threads(prev)


def test_two_threads_on_one_caster_get_their_own_answers(dem, batches, pooled):
    caster = RayCaster.from_dem(dem)
    jobs = [("camera", "all"), ("incoherent", "all"), ("camera", "first"), ("small", "all")]
    expected = {j: unpooled_cast(dem, *batches[j[0]], mode=j[1]) for j in jobs}
    errors: list[BaseException] = []
    start = threading.Barrier(2)

    def worker(k: int) -> None:
        try:
            start.wait()
            for r in range(6):
                job = jobs[(k + r) % len(jobs)]
                assert_identical_hits(caster.cast(*batches[job[0]], mode=job[1]), expected[job])
        except BaseException as e:  # noqa: BLE001 - reported by the main thread
            errors.append(e)

    workers = [threading.Thread(target=worker, args=(k,)) for k in range(2)]
    for w in workers:
        w.start()
    for w in workers:
        w.join()
    assert not errors, errors[0]
    assert len(rc._SCRATCH._free) <= rc._SCRATCH_MAX_BUFFERS


def test_pool_lends_distinct_buffers_within_bounds():
    pool = rc._ScratchPool(max_buffers=2, max_bytes=8 * 1000)
    a, b = pool.take(100), pool.take(100)
    assert not np.shares_memory(a, b)
    pool.give(a)
    pool.give(b)
    assert pool.take(50) is not None and pool.nbytes == 800  # one lent, one kept
    big = pool.take(900)  # none fits: a new one
    assert len(big) == 900
    pool.give(big)
    assert pool.nbytes <= 8 * 1000 and len(pool._free) <= 2
    pool.give(np.empty(2000))  # over the byte bound on its own: not kept
    assert all(len(x) < 2000 for x in pool._free)
    kept = pool._free[0]
    assert pool.take(len(kept)) is kept  # the smallest that fits is reused
    with pool.lend(10) as buf:
        assert len(buf) >= 10
    assert any(x is buf for x in pool._free)


def test_only_casts_above_the_threshold_use_the_pool(dem, batches, monkeypatch):
    monkeypatch.setattr(rc, "_SCRATCH", rc._ScratchPool())
    monkeypatch.setattr(rc, "_SCRATCH_MIN_BYTES", 1 << 20)
    caster = RayCaster.from_dem(dem)
    o, d = batches["camera"]
    first = caster.cast(o, d)
    assert rc._SCRATCH.nbytes >= len(o) * (rc._FIRST_PASS_HITS_RUNS + 1) * 8
    assert_identical_hits(caster.cast(o, d), first)
    kept = list(rc._SCRATCH._free)
    small = caster.cast(*batches["small"])  # under _SCRATCH_MIN_BYTES: allocated
    assert all(x is y for x, y in zip(rc._SCRATCH._free, kept, strict=True))
    assert_identical_hits(small, unpooled_cast(dem, *batches["small"]))
