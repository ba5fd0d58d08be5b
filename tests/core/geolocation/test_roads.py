from __future__ import annotations

import warnings

import numpy as np
import pytest
import shapely
from shapely import LineString, Point

from demtrack.core.errors import DemtrackError, InputFileError
from demtrack.core.geolocation.roads import RoadCandidate, RoadNetwork
from demtrack.core.terrain.dem import Dem
from demtrack.core.terrain.grid import GridSpec


def plane_dem(a=0.0, b=0.0, c=0.0, bounds=(-100.0, -20.0, 100.0, 300.0), cell=2.0) -> Dem:
    """DEM of the plane z = a x + b y + c (exact for the bilinear surface)."""
    grid = GridSpec.covering(*bounds, cell)
    x, y = grid.centres()
    return Dem(grid, (a * x + b * y + c).astype(np.float32))


def cross_2d(o, d, p, q):
    """Crossing of the half-line o + t d with the segment p-q, by Cramer's rule: (t, s)."""
    e = q - p
    det = d[0] * (-e[1]) - d[1] * (-e[0])
    rhs = p - o
    t = (rhs[0] * (-e[1]) - rhs[1] * (-e[0])) / det
    s = (d[0] * rhs[1] - d[1] * rhs[0]) / det
    return t, s


def test_crossing_on_a_plane_matches_the_hand_computed_intersection():
    a, b, c = 0.02, -0.03, 5.0
    dem = plane_dem(a, b, c)
    o = np.array([3.0, -5.0, 40.0])
    d = np.array([0.3, 1.0, -0.2])  # deliberately not unit length
    p, q = np.array([-60.0, 40.0]), np.array([70.0, 75.0])
    roads = RoadNetwork.from_coordinates([np.array([p, q])])
    cands = roads.ray_candidates(o, d, dem, cutoff_m=500.0)
    assert len(cands) == 1
    t, s = cross_2d(o[:2], d[:2], p, q)
    assert 0 < s < 1
    x, y = o[:2] + t * d[:2]
    z_ray = o[2] + t * d[2]
    z_ground = a * x + b * y + c
    cand = cands[0]
    assert isinstance(cand, RoadCandidate)
    np.testing.assert_allclose(cand.p_enu, [x, y, z_ground], atol=1e-5)
    assert cand.range_m == pytest.approx(t * np.linalg.norm(d), abs=1e-9)
    assert cand.vertical_gap_m == pytest.approx(abs(z_ground - z_ray), abs=1e-5)
    assert cand.road_index == 0
    best = roads.best_candidate(o, d, dem, cutoff_m=500.0)
    assert best is not None and np.allclose(best.p_enu, cand.p_enu)


def test_rule_picks_the_far_road_where_the_ray_meets_the_ground():
    # The paper's case: the ray crosses a near road high above it (it would first meet a
    # tree crown standing between the roads) and reaches the ground on the far road.
    grid = GridSpec.covering(-40.0, -10.0, 40.0, 200.0, 1.0)
    x, y = grid.centres()
    elev = np.zeros(grid.shape, np.float32)
    elev[(np.abs(x) < 10) & (y > 40) & (y < 50)] = 8.0  # a tree block between the roads
    dem = Dem(grid, elev)
    o = np.array([0.0, 0.0, 20.0])
    d = np.array([0.0, 45.0, -12.0])  # tree top at y = 45, ground at y = 75
    roads = RoadNetwork.from_coordinates(
        [
            np.array([[-30.0, 20.0], [30.0, 20.0]]),  # near road, in front of the tree
            np.array([[-30.0, 75.0], [30.0, 75.0]]),  # far road, the true ground point
            np.array([[-30.0, 150.0], [30.0, 150.0]]),  # beyond: the ray is underground
        ],
        names=("near", "far", "beyond"),
    )
    cands = roads.ray_candidates(o, d, dem, cutoff_m=1000.0)
    assert [c.road_index for c in cands] == [0, 1, 2]  # sorted by range
    slope = 12.0 / 45.0
    expected_gaps = [20.0 - slope * 20.0, 0.0, abs(20.0 - slope * 150.0)]
    np.testing.assert_allclose([c.vertical_gap_m for c in cands], expected_gaps, atol=1e-6)
    best = roads.best_candidate(o, d, dem, cutoff_m=1000.0)
    assert best is not None and best.road_index == 1
    assert roads.names[best.road_index] == "far"
    np.testing.assert_allclose(best.p_enu, [0.0, 75.0, 0.0], atol=1e-9)


def test_rule_picks_the_smallest_gap_not_the_nearest_or_farthest_on_a_slope():
    # Uphill plane: the ray reaches the ground between two other roads, so neither the
    # nearest nor the farthest crossing is the answer.
    a, b, c = 0.0, 0.1, 0.0
    dem = plane_dem(a, b, c)
    o = np.array([5.0, 0.0, 30.0])
    d = np.array([0.0, 1.0, -0.2])  # z_ray = 30 - 0.2 y meets z = 0.1 y at y = 100
    ys = [40.0, 100.0, 160.0, 220.0]
    roads = RoadNetwork.from_coordinates([np.array([[-50.0, yy], [50.0, yy]]) for yy in ys])
    cands = roads.ray_candidates(o, d, dem, cutoff_m=1000.0)
    gaps = [abs(0.1 * yy - (30.0 - 0.2 * yy)) for yy in ys]
    np.testing.assert_allclose([cc.vertical_gap_m for cc in cands], gaps, atol=1e-5)
    best = roads.best_candidate(o, d, dem, cutoff_m=1000.0)
    assert best is not None and best.road_index == 1
    np.testing.assert_allclose(best.p_enu, [5.0, 100.0, 10.0], atol=1e-5)
    assert best.range_m == pytest.approx(100.0 * np.sqrt(1.04), abs=1e-9)


def test_a_winding_road_gives_one_candidate_per_crossing():
    dem = plane_dem()
    o = np.array([0.0, 0.0, 10.0])
    d = np.array([0.0, 1.0, -0.1])
    zigzag = np.array([[-20.0, 30.0], [20.0, 50.0], [-20.0, 70.0], [20.0, 90.0]])
    roads = RoadNetwork.from_coordinates([zigzag])
    cands = roads.ray_candidates(o, d, dem, cutoff_m=1000.0)
    np.testing.assert_allclose([cc.p_enu[1] for cc in cands], [40.0, 60.0, 80.0], atol=1e-9)
    assert all(cc.road_index == 0 for cc in cands)
    best = roads.best_candidate(o, d, dem, cutoff_m=1000.0)
    assert best is not None and best.p_enu[1] == pytest.approx(80.0)  # z_ray = 2 there


def test_no_road_crossed_gives_no_candidate():
    dem = plane_dem()
    roads = RoadNetwork.from_coordinates([np.array([[10.0, 0.0], [10.0, 200.0]])])
    o, d = np.array([0.0, 0.0, 10.0]), np.array([0.0, 1.0, -0.1])  # parallel to the road
    assert roads.ray_candidates(o, d, dem, 1000.0) == []
    assert roads.best_candidate(o, d, dem, 1000.0) is None
    # Looking away from the road: the ground track runs south, the road is to the north.
    north = RoadNetwork.from_coordinates([np.array([[-50.0, 50.0], [50.0, 50.0]])])
    assert north.best_candidate(o, np.array([0.0, -1.0, -0.1]), dem, 1000.0) is None
    # Straight down: the ground track is a point.
    assert north.best_candidate(o, np.array([0.0, 0.0, -1.0]), dem, 1000.0) is None


def test_range_cutoff_is_honoured():
    dem = plane_dem()
    roads = RoadNetwork.from_coordinates([np.array([[-50.0, 60.0], [50.0, 60.0]])])
    o, d = np.array([0.0, 0.0, 80.0]), np.array([0.0, 0.6, -0.8])  # range 100 at y = 60
    assert roads.best_candidate(o, d, dem, cutoff_m=99.9) is None
    best = roads.best_candidate(o, d, dem, cutoff_m=100.1)
    assert best is not None and best.range_m == pytest.approx(100.0)
    assert best.vertical_gap_m == pytest.approx(0.0, abs=1e-9)


def test_crossings_without_dem_data_are_left_out():
    grid = GridSpec.covering(-50.0, -10.0, 50.0, 100.0, 1.0)
    x, y = grid.centres()
    elev = np.zeros(grid.shape, np.float32)
    elev[np.abs(y - 30.0) < 3.0] = np.nan  # a hole under the first road
    dem = Dem(grid, elev)
    roads = RoadNetwork.from_coordinates(
        [
            np.array([[-40.0, 30.0], [40.0, 30.0]]),  # over the hole
            np.array([[-40.0, 60.0], [40.0, 60.0]]),  # on data
            np.array([[-40.0, 150.0], [40.0, 150.0]]),  # off the DEM
        ]
    )
    cands = roads.ray_candidates(np.array([0.0, 0.0, 10.0]), np.array([0.0, 1.0, -0.1]), dem, 1e3)
    assert [cc.road_index for cc in cands] == [1]


def test_distance_matches_shapely_distance_to_the_nearest_line():
    rng = np.random.default_rng(0)
    lines = [rng.uniform(-100, 100, (int(rng.integers(2, 6)), 2)) for _ in range(12)]
    roads = RoadNetwork.from_coordinates(lines)
    x, y = rng.uniform(-150, 150, (2, 500))
    got = roads.distance_m(x, y)
    union = shapely.union_all([LineString(c) for c in lines])
    want = shapely.distance(shapely.points(x, y), union)
    assert got.shape == (500,)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    # A point on a vertex is on the road; scalars work too.
    assert float(roads.distance_m(lines[3][1, 0], lines[3][1, 1])) == 0.0


def test_empty_network_has_no_candidates_and_infinite_distance():
    roads = RoadNetwork(())
    assert len(roads) == 0
    dem = plane_dem()
    assert roads.best_candidate(np.zeros(3) + [0, 0, 10], np.array([0, 1, -0.1]), dem, 1e3) is None
    np.testing.assert_array_equal(roads.distance_m(np.array([1.0, 2.0]), np.zeros(2)), np.inf)


def test_names_and_widths_default_and_are_kept():
    seg = np.array([[0.0, 0.0], [10.0, 0.0]])
    roads = RoadNetwork.from_coordinates([seg, seg + 5])
    assert roads.names == ("road 0", "road 1")
    assert roads.widths_m == (6.0, 6.0)
    named = RoadNetwork.from_coordinates([seg, seg + 5], ["Main St", "Forbes Ave"], [7.0, 9.5])
    assert named.names == ("Main St", "Forbes Ave") and named.widths_m == (7.0, 9.5)
    # Vertices given as (k, 3) keep only x, y.
    three_d = RoadNetwork.from_coordinates([np.column_stack([seg, [1.0, 2.0]])])
    assert not three_d.lines[0].has_z


def _nan_line() -> LineString:
    with warnings.catch_warnings():  # shapely warns about the NaN it is asked to store
        warnings.simplefilter("ignore", RuntimeWarning)
        return LineString([(0.0, 0.0), (np.nan, 1.0)])


@pytest.mark.parametrize(
    "make_line",
    [
        lambda: Point(0.0, 0.0),
        LineString,  # empty
        lambda: [(0.0, 0.0), (1.0, 1.0)],  # a bare list of points is not a LineString
        _nan_line,
    ],
    ids=["point", "empty-line", "list", "nan"],
)
def test_malformed_lines_are_rejected(make_line):
    with pytest.raises(InputFileError, match="road 0"):
        RoadNetwork((make_line(),))


@pytest.mark.parametrize(
    "coords",
    [
        np.array([[0.0, 0.0]]),  # one vertex
        np.array([0.0, 1.0, 2.0]),  # not (k, 2)
        np.zeros((3, 1)),
        np.array([[0.0, 0.0], [np.inf, 3.0]]),
        np.zeros((0, 2)),
    ],
    ids=["one-vertex", "1-d", "one-column", "inf", "empty"],
)
def test_malformed_coordinates_are_rejected_with_a_clear_error(coords):
    good = np.array([[0.0, 0.0], [1.0, 0.0]])
    with pytest.raises(InputFileError, match="road 1") as info:
        RoadNetwork.from_coordinates([good, coords])
    assert isinstance(info.value, DemtrackError) and "\n" not in str(info.value)


def test_names_or_widths_of_the_wrong_length_are_rejected():
    seg = np.array([[0.0, 0.0], [10.0, 0.0]])
    with pytest.raises(InputFileError, match="names"):
        RoadNetwork.from_coordinates([seg, seg + 1], names=["only one"])
    with pytest.raises(InputFileError, match="widths"):
        RoadNetwork.from_coordinates([seg], widths_m=[5.0, 6.0])


def test_clipping_to_a_box_keeps_exactly_the_part_inside():
    from demtrack.core.geolocation.roads import _clip_to_box

    rng = np.random.default_rng(3)
    box = (-10.0, -5.0, 20.0, 15.0)
    start = rng.uniform(-40, 50, (2000, 2))
    stop = rng.uniform(-40, 50, (2000, 2))
    stop[:50, 0] = start[:50, 0]  # vertical
    stop[50:100, 1] = start[50:100, 1]  # horizontal
    stop[100:110] = start[100:110]  # a point
    inside = rng.uniform([-10, -5], [20, 15], (100, 2))
    start[110:160], stop[110:160] = inside[:50], inside[50:]  # wholly inside: unchanged
    a, b, over = _clip_to_box(start, stop, box)
    assert np.array_equal(a[110:160], start[110:160]) and np.array_equal(b[110:160], stop[110:160])
    ts = np.linspace(0.0, 1.0, 401)
    for k in range(len(start)):
        pts = start[k] + ts[:, None] * (stop[k] - start[k])
        ok = (
            (pts[:, 0] >= box[0])
            & (pts[:, 0] <= box[2])
            & (pts[:, 1] >= box[1])
            & (pts[:, 1] <= box[3])
        )
        if not over[k]:
            assert not ok.any(), k
            continue
        seg = (
            shapely.LineString([start[k], stop[k]])
            if not np.array_equal(start[k], stop[k])
            else None
        )
        clipped = shapely.box(*box).intersection(seg) if seg is not None else None
        for p in (a[k], b[k]):  # ends inside the box (to rounding), on the segment
            assert box[0] - 1e-9 <= p[0] <= box[2] + 1e-9 and box[1] - 1e-9 <= p[1] <= box[3] + 1e-9
            if seg is not None:
                assert seg.distance(shapely.Point(p)) < 1e-9
        if clipped is not None and not clipped.is_empty and clipped.length > 0:
            assert np.hypot(*(b[k] - a[k])) == pytest.approx(clipped.length, abs=1e-9)
