"""Batched paths of the tracker against their one-at-a-time references.

The smoother's cached steps, the stacked gating of every track against a scan and the
vectorised pairing of simultaneous fixes must give what the plain per-item code gives:
bit for bit where the arithmetic is the same, to round-off where it is vectorised.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from demtrack.core.tracking.config import TrackerConfig
from demtrack.core.tracking.fusion import _pair_scalar, _pair_vectorised, fuse_measurements
from demtrack.core.tracking.hypothesiser import CandidateBlock, GatedNearestHit, gate_d2
from demtrack.core.tracking.kalman import KalmanFilter
from demtrack.core.tracking.motion import ConstantVelocity
from demtrack.core.tracking.protocols import Candidates, Measurement
from demtrack.core.tracking.types import Fix


def _cands(rng: np.random.Generator, m: int) -> Candidates:
    z = np.column_stack([rng.uniform(-20, 20, (m, 2)), rng.uniform(0, 3, m)])
    a = rng.normal(size=(m, 2, 2))
    cov = a @ np.swapaxes(a, 1, 2) + 0.2 * np.eye(2)
    return Candidates(z, np.sqrt(cov[:, 0, 0]), np.full(m, 1 / m), False, cov)


def test_cached_smoother_steps_equal_the_recomputed_ones():
    rng = np.random.default_rng(0)
    kf = KalmanFilter(ConstantVelocity(2.0), 3.0, history_len=6)
    state = kf.initiate(_cands(rng, 1), 0, 0.0, rng)
    t = 0.0
    for _ in range(15):
        t += float(rng.choice([0.1, 0.2, 0.1, 0.35]))
        state = kf.update(kf.predict(state, t, rng), _cands(rng, 1), 0, rng)
        assert len(state.gains) == len(state.history) - 1
        bare = dataclasses.replace(state, gains=())  # forces the recomputation
        for n in range(len(state.history) + 2):
            got, ref = kf.revise(state, n), kf.revise(bare, n)
            assert len(got) == len(ref) == min(n, len(state.history))
            for a, b in zip(got, ref, strict=True):
                assert a.tobytes() == b.tobytes()


def test_stacked_gating_equals_per_measurement_gating():
    rng = np.random.default_rng(1)
    hyp = GatedNearestHit(gate_d2(0.99))
    for _ in range(30):
        items = [_cands(rng, int(rng.integers(1, 4))) for _ in range(int(rng.integers(1, 6)))]
        block = CandidateBlock.stack(items)
        n_tracks = int(rng.integers(1, 5))
        means = rng.uniform(-20, 20, (n_tracks, 2))
        a = rng.normal(size=(n_tracks, 2, 2))
        covs = a @ np.swapaxes(a, 1, 2) + np.eye(2)
        allowed = rng.random((n_tracks, len(items))) < 0.8
        rows = hyp.hypothesise_tracks(means, covs, block, allowed)
        n_gated = 0
        for i in range(n_tracks):
            assert hyp.hypothesise_block(means[i], covs[i], block, allowed[i]) == rows[i]
            for j, cands in enumerate(items):
                ref = hyp.hypothesise(means[i], covs[i], cands, j) if allowed[i, j] else None
                got = rows[i][j]
                assert (got is None) == (ref is None)
                if ref is not None:
                    n_gated += 1
                    assert got.measurement_index == j
                    assert got.candidate_index == ref.candidate_index
                    assert got.distance2 == ref.distance2  # the same solve, bit for bit
        assert n_gated <= n_tracks * len(items)


def _fix(rng, sensor, origin, target, t=1.0, idx=0, cls="vehicle"):
    d = np.asarray(target, float) - np.asarray(origin, float)
    hit = np.asarray(target, float) + rng.normal(0, 0.3, 3) * [1, 1, 0]
    crown = hit + [3.0, -2.0, 4.0]
    return Fix(t, sensor, cls, idx, origin, d, [crown, hit], [1.5, 0.8], road_hit_enu=None)


def test_vectorised_pairing_matches_the_scalar_one():
    rng = np.random.default_rng(2)
    config = TrackerConfig()
    cam_a, cam_b = np.array([-150.0, 0.0, 20.0]), np.array([0.0, -180.0, 25.0])
    n_pairs = 0
    for _ in range(10):
        targets = [np.array([*rng.uniform(-40, 40, 2), 0.0]) for _k in range(4)]
        fa = [_fix(rng, "a", cam_a, p, idx=k) for k, p in enumerate(targets)]
        fb = [_fix(rng, "b", cam_b, p, idx=10 + k) for k, p in enumerate(targets[::-1])]
        fa.append(_fix(rng, "a", cam_a, [60.0, 60.0, 0.0], idx=9, cls="human"))  # no partner
        ref = _pair_scalar(fa, fb, config)
        got = _pair_vectorised(fa, fb, config)
        assert [(r, c) for r, c, _ in got] == [(r, c) for r, c, _ in ref]
        for (_, _, (x, mx)), (_, _, (y, my)) in zip(got, ref, strict=True):
            assert abs(mx - my) < 1e-9
            np.testing.assert_allclose(x.hits_enu, y.hits_enu, rtol=0, atol=1e-9)
            np.testing.assert_allclose(x.hit_cov_en_m2, y.hit_cov_en_m2, rtol=1e-9, atol=1e-12)
            np.testing.assert_allclose(x.hit_sigma_m, y.hit_sigma_m, rtol=1e-9)
            assert (x.sensor, x.t_s, x.detection_index) == (y.sensor, y.t_s, y.detection_index)
            assert x.direction_enu.tobytes() == y.direction_enu.tobytes()
        n_pairs += len(got)
        # and through the public entry point: every real pair fused, the human left alone
        meas = [Measurement(f, (f.detection_index,), (f.sensor,)) for f in fa + fb]
        out = fuse_measurements(meas, config)
        assert sum(len(m.indices) == 2 for m in out) == len(got)
    assert n_pairs >= 30  # most of the 4 x 10 true pairs triangulate
