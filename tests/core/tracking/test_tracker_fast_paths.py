"""The tracker's fast paths against the forms they replaced (same answers, same bits)."""

from __future__ import annotations

import numpy as np
import pytest
from test_tracking_batched import _fix

from demtrack.core.tracking import association
from demtrack.core.tracking.association import GlobalNearestNeighbour
from demtrack.core.tracking.config import TrackerConfig
from demtrack.core.tracking.fusion import (
    _fix_arrays,
    _fused_fix,
    _screen_pairs,
    _triangulate_screened,
)
from demtrack.core.tracking.hypothesiser_kernels import gate_kernel
from demtrack.core.tracking.protocols import MissedDetection, SingleHypothesis
from demtrack.core.tracking.reference import gate_reference
from demtrack.core.tracking.tracker import _nearest_height


def _spd(rng, n):
    a = rng.normal(size=(n, 2, 2))
    return a @ np.swapaxes(a, 1, 2) + 0.05 * np.eye(2)


@pytest.mark.parametrize("seed", range(5))
def test_gate_kernel_equals_its_numpy_twin_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    for _ in range(100):
        t, n = int(rng.integers(1, 6)), int(rng.integers(1, 5))
        sizes = rng.integers(1, 4, n)
        c = int(sizes.sum())
        slots = np.full((n, int(sizes.max())), c, dtype=np.intp)
        start = 0
        for j, m in enumerate(sizes):
            slots[j, :m] = np.arange(start, start + m)
            start += m
        args = (
            rng.normal(0, 20, (t, 2)),
            _spd(rng, t),
            rng.normal(0, 20, (c, 2)),
            _spd(rng, c),
            slots,
            rng.random((t, n)) < 0.8,
        )
        if rng.random() < 0.2:  # a NaN candidate: argmin's pick, the first NaN
            args[2][rng.integers(c)] = np.nan
        if rng.random() < 0.2:  # a singular innovation covariance: inf or NaN, no error
            args[1][0] = 0.0
            args[3][0] = 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            got, ref = gate_kernel(*args), gate_reference(*args)
        np.testing.assert_array_equal(got[0], ref[0])
        assert got[1].tobytes() == ref[1].tobytes()


def _solver_only(hyps, m, miss_cost, monkeypatch):
    with monkeypatch.context() as mp:
        mp.setattr(association, "_obvious", lambda h, c: None)
        return GlobalNearestNeighbour(miss_cost).associate(hyps, m)


def test_association_shortcut_agrees_with_the_solver(monkeypatch):
    rng = np.random.default_rng(3)
    taken = 0
    for _ in range(3000):
        t, m = int(rng.integers(1, 5)), int(rng.integers(1, 5))
        rows = [
            [
                SingleHypothesis(j, 0, float(rng.choice([rng.uniform(0, 12), 9.0, 3.0])))
                if rng.random() < 0.3
                else None
                for j in range(m)
            ]
            for _ in range(t)
        ]
        quick = association._obvious(rows, 9.0)
        if quick is None:
            continue
        taken += 1
        ref = _solver_only(rows, m, 9.0, monkeypatch)
        for a, b in zip(quick, ref, strict=True):
            assert a is b or (isinstance(a, MissedDetection) and isinstance(b, MissedDetection))
    assert taken > 1000  # the shortcut is exercised, not only the solver


def test_nearest_height_picks_what_argmin_picks():
    rng = np.random.default_rng(5)
    for _ in range(2000):
        z = rng.normal(0, 3, (int(rng.integers(2, 5)), 3))
        if rng.random() < 0.3:
            z[1, :2] = z[0, :2]  # a tie: the first wins
        xy = rng.normal(0, 3, 2)
        near = int(np.argmin(np.sum((z[:, :2] - xy) ** 2, axis=1)))
        assert _nearest_height(z.tolist(), float(xy[0]), float(xy[1])) == z[near, 2]


def test_trusted_fused_fixes_equal_the_checked_ones():
    rng = np.random.default_rng(8)
    config = TrackerConfig()
    cam_a, cam_b = np.array([-150.0, 0.0, 20.0]), np.array([0.0, -180.0, 25.0])
    n = 0
    for _ in range(10):
        targets = [np.array([*rng.uniform(-40, 40, 2), 0.0]) for _k in range(3)]
        fa = [_fix(rng, "a", cam_a, p, idx=k) for k, p in enumerate(targets)]
        fb = [_fix(rng, "b", cam_b, p, idx=10 + k) for k, p in enumerate(targets)]
        screen = _screen_pairs(fa, fb, config, (_fix_arrays(fa), _fix_arrays(fb)))
        assert screen.cost.tobytes() == _screen_pairs(fa, fb, config).cost.tobytes()
        rows, cols = np.nonzero(screen.clear)
        got = _triangulate_screened(fa, fb, rows, cols, screen, config)
        for k, (fix, _) in enumerate(got):
            a, b = fa[rows[k]], fb[cols[k]]
            scores = [v for v in (a.score, b.score) if v is not None]
            p = screen.p_enu[rows[k], cols[k]]
            ref = _fused_fix(
                0.5 * (a.t_s + b.t_s),
                "+".join(sorted((a.sensor, b.sensor))),
                a.cls,
                a.detection_index,
                a.origin_enu,
                a.direction_enu,
                p[None, :],
                fix.hit_sigma_m.copy(),
                p if (a.road_hit_enu is not None or b.road_hit_enu is not None) else None,
                max(scores) if scores else None,
                fix.hit_cov_en_m2.copy(),
            )
            for name in ("t_s", "sensor", "cls", "detection_index", "score"):
                assert getattr(fix, name) == getattr(ref, name)
            for name in ("origin_enu", "direction_enu", "hits_enu", "hit_sigma_m", "hit_cov_en_m2"):
                x, y = getattr(fix, name), getattr(ref, name)
                assert x.tobytes() == y.tobytes() and x.shape == y.shape
                assert not x.flags.writeable
            n += 1
    assert n >= 20
