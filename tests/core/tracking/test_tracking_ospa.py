"""OSPA / GOSPA against hand-computed cases and a brute-force reference."""

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from demtrack.core.errors import TrackingError
from demtrack.core.tracking.ospa import gospa, ospa

X1 = np.array([[0.0, 0.0]])
Y2 = np.array([[3.0, 4.0], [10.0, 0.0]])


def test_hand_computed_p1():
    # one truth, two estimates: pair at 5 m, one extra estimate
    assert ospa(X1, Y2, c=10, p=1) == pytest.approx((5 + 10) / 2)
    g = gospa(X1, Y2, c=10, p=1)
    assert g.distance == pytest.approx(5 + 10 / 2)
    assert (g.localisation, g.missed, g.false) == (pytest.approx(5.0), 0, 1)


def test_hand_computed_p2_and_symmetry():
    assert ospa(X1, Y2, c=10, p=2) == pytest.approx(math.sqrt((25 + 100) / 2))
    assert ospa(Y2, X1, c=10, p=2) == pytest.approx(math.sqrt(62.5))
    assert gospa(X1, Y2, c=10, p=2).distance == pytest.approx(math.sqrt(25 + 50))


def test_cut_off_turns_a_far_pair_into_a_miss_and_a_false_target():
    far = np.array([[20.0, 0.0]])
    assert ospa(X1, far, c=10, p=2) == pytest.approx(10.0)
    g = gospa(X1, far, c=10, p=2)
    assert (g.missed, g.false, g.localisation) == (1, 1, 0.0)
    assert g.distance == pytest.approx(math.sqrt(100 / 2 + 100 / 2))


def test_empty_sets():
    e = np.zeros((0, 2))
    assert ospa(e, e) == 0.0
    assert ospa(e, Y2, c=7) == 7.0 and ospa(X1, e, c=7) == 7.0
    g = gospa(e, Y2, c=4, p=2)
    assert g.distance == pytest.approx(math.sqrt(16 / 2 * 2)) and g.false == 2
    assert gospa(e, e).distance == 0.0


def test_bad_parameters():
    with pytest.raises(TrackingError):
        ospa(X1, Y2, c=0)
    with pytest.raises(TrackingError):
        gospa(X1, Y2, p=0.5)
    with pytest.raises(TrackingError):
        ospa(X1, np.zeros((1, 3)))


def _brute_ospa(x, y, c, p):
    if len(x) == 0 and len(y) == 0:
        return 0.0
    if len(x) == 0 or len(y) == 0:
        return c
    if len(x) > len(y):
        x, y = y, x
    m, n = len(x), len(y)
    best = min(
        sum(min(c, np.linalg.norm(x[i] - y[j])) ** p for i, j in enumerate(perm))
        for perm in itertools.permutations(range(n), m)
    )
    return ((best + c**p * (n - m)) / n) ** (1 / p)


def _brute_gospa(x, y, c, p):
    """Minimum over every partial assignment (the definition, alpha = 2)."""
    m, n = len(x), len(y)
    best = c**p / 2 * (m + n)
    for k in range(1, min(m, n) + 1):
        for xs in itertools.combinations(range(m), k):
            for ys in itertools.permutations(range(n), k):
                d = sum(np.linalg.norm(x[i] - y[j]) ** p for i, j in zip(xs, ys, strict=True))
                best = min(best, d + c**p / 2 * (m + n - 2 * k))
    return best ** (1 / p)


pts = st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20)), min_size=0, max_size=4)


@given(pts, pts, st.floats(1.0, 15.0), st.sampled_from([1.0, 2.0, 3.0]))
@settings(max_examples=60, deadline=None)
def test_matches_brute_force(x, y, c, p):
    x = np.array(x, dtype=float).reshape(-1, 2)
    y = np.array(y, dtype=float).reshape(-1, 2)
    assert ospa(x, y, c, p) == pytest.approx(_brute_ospa(x, y, c, p), rel=1e-9, abs=1e-9)
    assert gospa(x, y, c, p).distance == pytest.approx(_brute_gospa(x, y, c, p), rel=1e-9, abs=1e-9)


@given(pts, pts, pts)
@settings(max_examples=40, deadline=None)
def test_triangle_inequality(a, b, z):
    a, b, z = (np.array(v, dtype=float).reshape(-1, 2) for v in (a, b, z))
    for f in (lambda u, v: ospa(u, v, 5.0, 2.0), lambda u, v: gospa(u, v, 5.0, 2.0).distance):
        assert f(a, z) <= f(a, b) + f(b, z) + 1e-9
