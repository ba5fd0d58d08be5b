"""Hypothesiser, GNN associator, initiator, deleter."""

import numpy as np
import pytest
from scipy.stats import chi2

from demtrack.core.errors import TrackingError
from demtrack.core.tracking.association import GlobalNearestNeighbour
from demtrack.core.tracking.deletion import CoastTimeDeleter
from demtrack.core.tracking.hypothesiser import GatedNearestHit, gate_d2
from demtrack.core.tracking.initiation import MOfNInitiator
from demtrack.core.tracking.protocols import Candidates, MissedDetection, SingleHypothesis


def _cands(points, sigma=1.0):
    z = np.asarray(points, dtype=float)
    return Candidates(z, np.full(len(z), sigma), np.full(len(z), 1 / len(z)), False)


def test_gate_is_the_chi2_quantile():
    for prob in (1e-9, 0.1, 0.5, 0.9, 0.99, 0.999999):
        assert gate_d2(prob) == pytest.approx(chi2.ppf(prob, 2), rel=1e-12)
    assert gate_d2(0.99) == pytest.approx(-2 * np.log(0.01))  # 2 dof closed form
    with pytest.raises(TrackingError):
        gate_d2(1.0)


def test_hypothesiser_scores_the_best_hit_and_gates():
    hyp = GatedNearestHit(gate_d2(0.99))
    cov = np.eye(2) * 3.0
    # crown 8 m away along the ray, ground 1 m away: the ground hit is chosen
    h = hyp.hypothesise(np.zeros(2), cov, _cands([[0, 8, 4], [1, 0, 0]]), 5)
    assert h == SingleHypothesis(5, 1, pytest.approx(1.0 / 4.0))
    assert hyp.hypothesise(np.zeros(2), cov, _cands([[0, 8, 4]]), 0) is None


def test_gnn_resolves_conflicts_and_reports_misses():
    gnn = GlobalNearestNeighbour(miss_cost=9.0)
    h = lambda j, d2: SingleHypothesis(j, 0, d2)  # noqa: E731
    # both tracks want measurement 0; track 0 has no alternative, track 1 has m1
    rows = [[h(0, 1.0), None], [h(0, 0.5), h(1, 2.0)], [None, None]]
    out = gnn.associate(rows, 2)
    assert out[0].measurement_index == 0
    assert out[1].measurement_index == 1
    assert isinstance(out[2], MissedDetection)
    # a worse-than-miss pairing is never forced
    assert isinstance(gnn.associate([[h(0, 10.0)]], 1)[0], MissedDetection)
    assert gnn.associate([], 3) == []


def test_m_of_n_initiator_and_coast_deleter():
    ini = MOfNInitiator(m=3, window_s=1.0, per_candidate=True)
    assert ini.seeds(_cands([[0, 0, 0], [1, 1, 1]])) == [0, 1]
    assert MOfNInitiator(per_candidate=False).seeds(_cands([[0, 0, 0], [1, 1, 1]])) == [None]
    assert not ini.confirmed(2, 0.5) and ini.confirmed(3, 0.5)
    assert not ini.expired(2, 0.9) and ini.expired(2, 1.1) and not ini.expired(3, 2.0)
    with pytest.raises(TrackingError):
        MOfNInitiator(m=0)
    deleter = CoastTimeDeleter({"vehicle": 2.0, "human": 5.0})
    assert deleter.delete("vehicle", 2.5) and not deleter.delete("human", 2.5)
    with pytest.raises(TrackingError):
        deleter.delete("boat", 1.0)
