"""Motion models, Kalman and particle filters, measurement models, road network."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely import LineString

from demtrack.core.errors import TrackingError
from demtrack.core.tracking.kalman import GaussianState, KalmanFilter
from demtrack.core.tracking.measurement import AllHits, FirstHit, HitMixture, LastHit, RoadHit
from demtrack.core.tracking.motion import (
    ConstantVelocity,
    ConstantVelocityParticles,
    allocate_counts,
)
from demtrack.core.tracking.particle import (
    ParticleFilter,
    mixture_likelihood,
    systematic_resample,
)
from demtrack.core.tracking.protocols import Candidates
from demtrack.core.tracking.roads import RoadGraph, RoadParticleMotion
from demtrack.core.tracking.types import Fix


def _cands(points, sigma=0.5, mixture=False):
    z = np.asarray(points, dtype=float)
    m = len(z)
    return Candidates(z, np.full(m, sigma), np.full(m, 1.0 / m), mixture)


# ----------------------------------------------------------------------- motion
def test_cv_transition_and_noise_are_the_textbook_ones():
    cv = ConstantVelocity(2.0)
    f = cv.transition(0.5)
    np.testing.assert_allclose(f @ [1, 2, 3, 4], [2.5, 4, 3, 4])
    q = cv.covariance(0.5)
    np.testing.assert_allclose(q[0, 0], 2.0 * 0.5**3 / 3)
    np.testing.assert_allclose(q[0, 2], 2.0 * 0.5**2 / 2)
    np.testing.assert_allclose(q[3, 3], 2.0 * 0.5)
    assert q[0, 1] == 0 and q[0, 3] == 0
    # Q of two half steps composed equals Q of the whole step (the model is consistent)
    f1 = cv.transition(0.25)
    np.testing.assert_allclose(f1 @ cv.covariance(0.25) @ f1.T + cv.covariance(0.25), q, atol=1e-12)
    with pytest.raises(TrackingError):
        ConstantVelocity(0.0)


def test_cv_particles_match_the_kalman_prediction_statistically():
    rng = np.random.default_rng(0)
    cvp = ConstantVelocityParticles(q_m2_s3=3.0, init_speed_sigma_m_s=2.0)
    parts = np.tile([1.0, 2.0, 3.0, -1.0], (40000, 1))
    out = cvp.propagate(parts, 0.8, rng)
    np.testing.assert_allclose(out.mean(axis=0), [1 + 2.4, 2 - 0.8, 3, -1], atol=0.02)
    cov = np.cov(out.T)
    np.testing.assert_allclose(cov, ConstantVelocity(3.0).covariance(0.8), atol=0.03)


@given(st.lists(st.floats(0.01, 1.0), min_size=1, max_size=6), st.integers(1, 500))
@settings(max_examples=50, deadline=None)
def test_allocate_counts_sums_and_rounds(w, n):
    w = np.array(w) / np.sum(w)
    c = allocate_counts(w, n)
    assert c.sum() == n
    assert np.all(np.abs(c - w * n) < 1.0)


# ------------------------------------------------------------------- measurement
def test_measurement_models_read_the_right_hits():
    fix = Fix(
        0.0,
        "c",
        "vehicle",
        0,
        [0, 0, 10],
        [1, 0, -1],
        [[5, 0, 5], [10, 0, 0], [20, 0, -10]],
        [0.3, 0.4, 0.5],
        road_hit_enu=[10, 0.2, 0],
    )
    np.testing.assert_array_equal(FirstHit().candidates(fix).z_enu, [[5, 0, 5]])
    np.testing.assert_array_equal(LastHit().candidates(fix).z_enu, [[20, 0, -10]])
    allc = AllHits().candidates(fix)
    assert allc.size == 3 and not allc.mixture
    mix = HitMixture().candidates(fix)
    assert mix.mixture and np.isclose(mix.weight.sum(), 1.0)
    road = RoadHit().candidates(fix)
    np.testing.assert_array_equal(road.z_enu, [[10, 0.2, 0]])
    assert road.sigma_m[0] == 0.3 and not road.mixture
    assert RoadHit(sigma_m=0.7).candidates(fix).sigma_m[0] == 0.7
    no_road = Fix(0.0, "c", "vehicle", 0, [0, 0, 10], [1, 0, -1], [[10, 0, 0]], [0.3])
    assert RoadHit().candidates(no_road).mixture
    empty = Fix(0.0, "c", "vehicle", 0, [0, 0, 10], [1, 0, 1], [], [])
    for model in (FirstHit(), LastHit(), AllHits(), HitMixture(), RoadHit()):
        assert model.candidates(empty) is None


# ------------------------------------------------------------------------ kalman
def _kf(**kw):
    return KalmanFilter(ConstantVelocity(1.0), init_speed_sigma_m_s=2.0, **kw)


def test_kalman_update_matches_the_information_form():
    kf = _kf()
    rng = np.random.default_rng(0)
    p0 = np.diag([4.0, 1.0, 2.0, 3.0])
    p0[0, 2] = p0[2, 0] = 0.5
    state = GaussianState(0.0, np.array([1.0, 2.0, 0.5, -0.5]), p0, 0.0)
    z = np.array([[2.0, 1.0, 3.0]])
    out = kf.update(state, _cands(z, sigma=0.8), 0, rng)
    h = np.hstack([np.eye(2), np.zeros((2, 2))])
    r_inv = np.eye(2) / 0.8**2
    p_post = np.linalg.inv(np.linalg.inv(p0) + h.T @ r_inv @ h)
    x_post = p_post @ (np.linalg.inv(p0) @ state.x + h.T @ r_inv @ z[0, :2])
    np.testing.assert_allclose(out.P, p_post, atol=1e-12)
    np.testing.assert_allclose(out.x, x_post, atol=1e-12)
    assert out.z_m == 3.0


def test_pda_with_one_hit_is_a_plain_update_and_ignores_a_far_crown():
    kf = _kf(clutter_density_per_m2=1e-9)
    rng = np.random.default_rng(0)
    state = GaussianState(0.0, np.array([0.0, 0.0, 1.0, 0.0]), np.eye(4), 0.0)
    near = [0.3, -0.2, 0.0]
    plain = kf.update(state, _cands([near]), 0, rng)
    pda1 = kf.update(state, _cands([near], mixture=True), 0, rng)
    np.testing.assert_allclose(pda1.x, plain.x, atol=1e-6)
    pda2 = kf.update(state, _cands([[8.0, 6.0, 4.0], near], mixture=True), 0, rng)
    np.testing.assert_allclose(pda2.x, plain.x, atol=1e-6)
    assert pda2.z_m == 0.0
    # all hits far: the clutter floor keeps the prediction (a coast)
    far = kf.update(state, _cands([[40.0, 0.0, 0.0]], mixture=True), 0, rng)
    assert far.x[0] < 0.3


def test_kalman_tracks_a_constant_velocity_target():
    rng = np.random.default_rng(0)
    kf = KalmanFilter(ConstantVelocity(0.05), init_speed_sigma_m_s=5.0)
    truth_v = np.array([3.0, -1.0])
    state = kf.initiate(_cands([[0, 0, 0]], sigma=0.3), 0, 0.0, rng)
    for k in range(1, 60):
        t = 0.1 * k
        state = kf.predict(state, t, rng)
        z = truth_v * t + 0.3 * rng.standard_normal(2)
        state = kf.update(state, _cands([[*z, 0.0]], sigma=0.3), 0, rng)
    np.testing.assert_allclose(state.x[2:], truth_v, atol=0.3)
    np.testing.assert_allclose(state.x[:2], truth_v * 5.9, atol=0.3)
    # the filter's own covariance is consistent with its error (NEES below 3-sigma bound)
    err = state.x - np.array([*(truth_v * 5.9), *truth_v])
    assert err @ np.linalg.solve(state.P, err) < 20.0


def test_rts_revision_of_a_straight_noiseless_track_is_exact():
    rng = np.random.default_rng(0)
    kf = _kf(history_len=6)
    state = kf.initiate(_cands([[0, 0, 0]], sigma=0.3), 0, 0.0, rng)
    for k in range(1, 20):
        t = 0.5 * k
        state = kf.predict(state, t, rng)
        state = kf.update(state, _cands([[2.0 * t, 1.0, 0]], sigma=0.3), 0, rng)
    revised = kf.revise(state, 4)
    assert len(revised) == 4
    np.testing.assert_allclose(revised[-1], state.x[:2])
    for k, xy in zip(range(16, 20), revised, strict=True):
        np.testing.assert_allclose(xy, [2.0 * 0.5 * k, 1.0], atol=0.05)
    plain = _kf()  # history_len 0: no smoothing
    s0 = plain.update(
        plain.initiate(_cands([[0, 0, 0]]), 0, 0.0, rng), _cands([[0.1, 0, 0]]), 0, rng
    )
    assert s0.history == () and plain.revise(s0, 3) == []


# ---------------------------------------------------------------------- particle
@given(st.lists(st.floats(0.0, 1.0), min_size=1, max_size=40), st.integers(0, 10_000))
@settings(max_examples=60, deadline=None)
def test_systematic_resampling_copies_floor_or_ceil_times(w, seed):
    w = np.array(w) + 1e-3
    w /= w.sum()
    idx = systematic_resample(w, np.random.default_rng(seed))
    counts = np.bincount(idx, minlength=len(w))
    n = len(w)
    assert counts.sum() == n
    assert np.all(counts >= np.floor(n * w) - 1e-9)
    assert np.all(counts <= np.ceil(n * w) + 1e-9)


def test_mixture_likelihood_is_the_analytic_density():
    cands = _cands([[0, 0, 0], [10, 0, 0]], sigma=2.0)
    xy = np.array([[0.0, 0.0], [3.0, 4.0]])
    got = mixture_likelihood(xy, cands, 1e-4)
    g = lambda d2: np.exp(-0.5 * d2 / 4.0) / (2 * np.pi * 4.0)  # noqa: E731
    np.testing.assert_allclose(
        got, [1e-4 + 0.5 * g(0) + 0.5 * g(100), 1e-4 + 0.5 * g(25) + 0.5 * g(49 + 16)]
    )
    only = mixture_likelihood(xy, cands, 0.0, only=1)
    np.testing.assert_allclose(only, [g(100), g(65)])


def test_particle_filter_carries_two_hypotheses_until_motion_decides():
    """A crown hit and a road hit: both survive one fix; the moving object settles it."""
    rng = np.random.default_rng(0)
    pf = ParticleFilter(ConstantVelocityParticles(1.0, 3.0), n_particles=600)
    crown, road = [0.0, 10.0, 3.0], [0.0, 0.0, 0.0]
    state = pf.initiate(_cands([crown, road], mixture=True), None, 0.0, rng)
    xy = pf.motion.positions(state.particles)
    near_crown = np.mean(np.linalg.norm(xy - crown[:2], axis=1) < 2)
    assert 0.4 < near_crown < 0.6
    # the object moves east at 2 m/s; later fixes see only the ground
    for k in range(1, 8):
        t = 0.2 * k
        state = pf.predict(state, t, rng)
        state = pf.update(state, _cands([[2.0 * t, 0.0, 0.0]], mixture=True), 0, rng)
    p, cov = pf.estimate(state)
    np.testing.assert_allclose(p[:2], [2.8, 0.0], atol=0.5)
    # the first, ambiguous point is settled by the particles' ancestry
    first = pf.revise(state, 8)[0]
    assert np.linalg.norm(first - road[:2]) < 1.0


def test_particle_estimate_is_the_dominant_mode_not_the_mean():
    rng = np.random.default_rng(0)
    pf = ParticleFilter(ConstantVelocityParticles(1.0, 1.0), n_particles=400)
    c = Candidates(
        np.array([[0.0, 0.0, 0.0], [20.0, 0.0, 0.0]]),
        np.array([0.5, 0.5]),
        np.array([0.7, 0.3]),
        True,
    )
    state = pf.initiate(c, None, 0.0, rng)
    p, _ = pf.estimate(state)
    assert np.linalg.norm(p[:2]) < 0.5
    mean, cov = pf.gaussian(state)
    assert 4.0 < mean[0] < 8.0 and cov[0, 0] > 50.0


# ------------------------------------------------------------------------- roads
def test_road_network_nodes_crossings_and_snaps():
    net = RoadGraph([LineString([(-50, 0), (50, 0)]), LineString([(0, -50), (0, 50)])])
    assert len(net.edges) == 4
    assert sorted(len(inc) for inc in net.incident) == [1, 1, 1, 1, 4]
    edge, s, lat = net.snap(np.array([[20.0, 1.5], [-3.0, -30.0]]))
    centre, normal = net.frame(edge, s)
    np.testing.assert_allclose(centre, [[20.0, 0.0], [0.0, -30.0]], atol=1e-9)
    np.testing.assert_allclose(np.abs(lat), [1.5, 3.0], atol=1e-9)
    np.testing.assert_allclose(centre + lat[:, None] * normal, [[20.0, 1.5], [-3.0, -30.0]])


def test_road_particles_wrap_around_a_loop_and_turn_at_dead_ends():
    rng = np.random.default_rng(0)
    square = LineString([(0, 0), (10, 0), (10, 10), (0, 10), (0, 0)])
    loop = RoadGraph([square])
    e, s, v, lat = loop.advance(
        np.array([0]), np.array([43.0]), np.array([2.0]), np.array([1.0]), rng
    )
    assert s[0] == pytest.approx(3.0) and v[0] == 2.0 and lat[0] == 1.0
    dead = RoadGraph([LineString([(0, 0), (10, 0)])])
    e, s, v, lat = dead.advance(
        np.array([0]), np.array([12.0]), np.array([2.0]), np.array([1.0]), rng
    )
    assert s[0] == pytest.approx(8.0) and v[0] == -2.0


def test_road_particle_motion_keeps_particles_on_the_road():
    rng = np.random.default_rng(0)
    net = RoadGraph([LineString([(-50, 0), (50, 0)]), LineString([(0, -50), (0, 50)])])
    motion = RoadParticleMotion(net, q_m2_s3=2.0, init_speed_sigma_m_s=8.0, max_lateral_m=2.0)
    parts = motion.initial(_cands([[3.0, 0.5, 0.0]], sigma=1.0), 300, rng)
    for _ in range(20):
        parts = motion.propagate(parts, 0.2, rng)
    xy = motion.positions(parts)
    off = np.minimum(np.abs(xy[:, 0]), np.abs(xy[:, 1]))
    assert np.all(off <= 2.0 + 1e-9)
    taken = motion.take(parts, np.array([0, 0, 1]))
    np.testing.assert_array_equal(taken.xy[0], taken.xy[1])


def test_road_network_rejects_empty_input():
    with pytest.raises(TrackingError):
        RoadGraph([])
