"""The tracker warm-up compiles exactly what tracking then calls."""

from __future__ import annotations

import numpy as np
import pytest
from test_tracking_batched import _fix

from demtrack.core.tracking import fusion_kernels, hypothesiser_kernels, kalman_kernels
from demtrack.core.tracking.methods import run_tracker
from demtrack.core.warm import warm_tracking as warm_up

KERNELS = (
    fusion_kernels.screen_pairs_kernel,
    fusion_kernels.triangulation_cov_kernel,
    kalman_kernels.predict_kernel,
    kalman_kernels.update_kernel,
    kalman_kernels.smoother_gain_kernel,
    kalman_kernels.rts_positions_kernel,
    hypothesiser_kernels.gate_kernel,
)


def test_after_warm_up_tracking_compiles_nothing():
    warm_up()
    before = [len(k.signatures) for k in KERNELS]
    assert all(n >= 1 for n in before)  # the warm-up reached every kernel
    rng = np.random.default_rng(4)
    cam_a, cam_b = np.array([-150.0, 0.0, 20.0]), np.array([0.0, -180.0, 25.0])
    fixes = []
    for k in range(20):
        target = np.array([1.5 * k, -0.5 * k, 0.0])
        for name, cam in (("a", cam_a), ("b", cam_b)):
            fixes.append(_fix(rng, name, cam, target, t=0.2 * k, idx=len(fixes)))
    tracks = run_tracker(fixes, "kalman")
    assert len(tracks) == 1 and len(tracks[0].points) > 10
    assert [len(k.signatures) for k in KERNELS] == before


def test_an_unknown_warm_up_part_is_a_one_line_error():
    with pytest.raises(ValueError, match="unknown warm-up part 'gating'"):
        warm_up(part="gating")
