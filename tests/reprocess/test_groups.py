"""Sensor groups: connected components of footprint overlap."""

from __future__ import annotations

import numpy as np

from demtrack.reprocess.groups import groups_of_masks, sensor_masks
from demtrack.reprocess.plan import segment_seed, split_quiet
from demtrack.reprocess.tasks import site_at


def _square(x0: int, y0: int, n: int = 10) -> np.ndarray:
    m = np.zeros((60, 60), bool)
    m[y0 : y0 + n, x0 : x0 + n] = True
    return m


def test_overlap_is_transitive_and_margins_join():
    masks = {"a": _square(0, 0), "b": _square(8, 0), "c": _square(16, 0), "d": _square(40, 40)}
    # a-b and b-c overlap: one chain; d alone
    assert groups_of_masks(masks, 0) == [("a", "b", "c"), ("d",)]
    e = {"e": _square(0, 0), "f": _square(13, 0)}  # 3 cells apart
    assert groups_of_masks(e, 1) == [("e",), ("f",)]
    assert groups_of_masks(e, 2) == [("e", "f")]  # each grown by 2: they meet


def test_the_twelve_camera_site_has_four_groups_of_three(site12_dir):
    site = site_at(str(site12_dir))
    masks = sensor_masks(site, site.sensors)
    assert all(m.any() for m in masks.values())  # every camera sees ground
    groups = groups_of_masks(masks, 20)
    assert groups == [tuple(f"c{3 * g + k + 1:02d}" for k in range(3)) for g in range(4)]


def test_quiet_split_and_seeds():
    t = np.array([0.0, 1.0, 2.0, 70.0, 71.0, 200.0])
    assert split_quiet(t, 60.0) == [(0, 3), (3, 5), (5, 6)]
    assert split_quiet(t, 1000.0) == [(0, 6)]
    assert split_quiet(np.zeros(0), 1.0) == []
    a = segment_seed(("c01", "c02"), 10.0)
    assert a == segment_seed(("c01", "c02"), 10.0)
    assert a != segment_seed(("c01", "c02"), 11.0) and a != segment_seed(("c01",), 10.0)
