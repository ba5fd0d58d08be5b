import numpy as np
import pytest

from demtrack.core.errors import DetectionError, TrackingError
from demtrack.core.tracking.types import Detection, Fix, Track, TrackPoint, TruthPath


def _fix(**kw):
    base = dict(
        t_s=1.0,
        sensor="cam",
        cls="vehicle",
        detection_index=0,
        origin_enu=[0, 0, 10],
        direction_enu=[0, 3, -4],
        hits_enu=[[0, 6, 2], [0, 7.5, 0]],
        hit_sigma_m=[0.5, 0.5],
    )
    base.update(kw)
    return Fix(**base)


def test_detection_foot_pixel_is_bottom_centre():
    d = Detection(0.5, "cam0", (10, 20, 30, 60), "human", 0.9, "7")
    assert d.foot_pixel == (20.0, 60.0)
    assert d.bbox == (10.0, 20.0, 30.0, 60.0)


@pytest.mark.parametrize(
    "kw",
    [
        dict(bbox=(30, 20, 10, 60)),
        dict(bbox=(0, 0, 1)),
        dict(bbox=(0, float("nan"), 1, 1)),
        dict(cls="dog"),
        dict(t_s=float("inf")),
        dict(sensor=""),
    ],
)
def test_detection_rejects_bad_values(kw):
    args = dict(t_s=0.0, sensor="c", bbox=(0, 0, 1, 1), cls="vehicle")
    args.update(kw)
    with pytest.raises(DetectionError):
        Detection(**args)


def test_fix_normalises_direction_and_freezes_arrays():
    f = _fix()
    np.testing.assert_allclose(f.direction_enu, [0, 0.6, -0.8])
    assert f.n_hits == 2
    assert not f.hits_enu.flags.writeable
    with pytest.raises(ValueError):
        f.hits_enu[0, 0] = 1.0


def test_fix_accepts_no_hits():
    f = _fix(hits_enu=[], hit_sigma_m=[])
    assert f.hits_enu.shape == (0, 3)
    assert f.hit_sigma_m.shape == (0,)


@pytest.mark.parametrize(
    "kw",
    [
        dict(direction_enu=[0, 0, 0]),
        dict(hit_sigma_m=[0.5]),
        dict(hit_sigma_m=[0.5, 0.0]),
        dict(hits_enu=[[0, 1]]),
        dict(origin_enu=[0, 0, np.nan]),
        dict(road_hit_enu=[1, 2]),
        dict(cls="car"),
    ],
)
def test_fix_rejects_bad_values(kw):
    with pytest.raises(TrackingError):
        _fix(**kw)


def test_track_arrays():
    pts = [TrackPoint(t, [t, 2 * t, 0], ("a",), (i,)) for i, t in enumerate([0.0, 0.5])]
    tr = Track(1, "human", pts, {"a"}, [(0.0, 0.5)])
    np.testing.assert_array_equal(tr.t_s, [0.0, 0.5])
    np.testing.assert_array_equal(tr.p_enu, [[0, 0, 0], [0.5, 1, 0]])
    assert tr.gaps == ((0.0, 0.5),)
    assert Track(2, "human", []).p_enu.shape == (0, 3)


def test_truth_interpolates_and_is_nan_outside():
    tp = TruthPath(1, "vehicle", [0.0, 2.0], [[0, 0, 0], [10, 20, 2]])
    np.testing.assert_allclose(tp.at(0.5), [[2.5, 5, 0.5]])
    assert np.all(np.isnan(tp.at([-1.0, 3.0])))
    with pytest.raises(TrackingError):
        TruthPath(1, "vehicle", [0.0, 0.0], [[0, 0, 0], [1, 1, 1]])
