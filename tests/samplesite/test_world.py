"""The sample world's crown heights: the near-tree evaluation equals evaluating every tree."""

from __future__ import annotations

import numpy as np

from demtrack.samplesite.world import make_world


def crown_z_everywhere(world, x, y):
    """Reference twin: every tree evaluated on every point (the straightforward loop)."""
    x = np.asarray(x, dtype=np.float64)
    y = np.asarray(y, dtype=np.float64)
    out = np.full(np.broadcast(x, y).shape, np.nan)
    g = world.ground_z(x, y)
    for t in world.trees:
        r2 = ((x - t.x) ** 2 + (y - t.y) ** 2) / t.r_m**2
        top = float(world.ground_z(t.x, t.y)) + t.top_m
        base = float(world.ground_z(t.x, t.y)) + t.base_m
        z = top - (top - base) * r2
        out = np.fmax(out, np.where((r2 <= 1.0) & (z > g), z, np.nan))
    return out


def test_crown_z_equals_every_tree_everywhere_bit_for_bit():
    world = make_world()
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-160, 160, 200_000), rng.uniform(-160, 160, 200_000)
    # Points on and just around every crown's rim, and at the trunks.
    for t in world.trees:
        a = rng.uniform(0, 2 * np.pi, 64)
        r = t.r_m * np.r_[np.ones(32), 1 + rng.uniform(-1e-12, 1e-12, 32)]
        x = np.r_[x, t.x + r * np.cos(a), t.x, t.x + t.r_m]
        y = np.r_[y, t.y + r * np.sin(a), t.y, t.y]
    got = world.crown_z(x, y)
    want = crown_z_everywhere(world, x, y)
    np.testing.assert_array_equal(got, want)
    assert np.isfinite(got).sum() > 1000  # the test sees crowns


def test_crown_z_keeps_shapes():
    world = make_world()
    t = world.trees[0]
    assert world.crown_z(t.x, t.y).shape == ()
    assert np.isfinite(world.crown_z(t.x, t.y))
    gx, gy = np.meshgrid(np.linspace(-150, 150, 40), np.linspace(-150, 150, 30))
    np.testing.assert_array_equal(world.crown_z(gx, gy), crown_z_everywhere(world, gx, gy))
    col = np.linspace(-150, 150, 25)[:, None]
    row = np.linspace(-150, 150, 7)[None, :]
    assert world.crown_z(col, row).shape == (25, 7)
    np.testing.assert_array_equal(world.crown_z(col, row), crown_z_everywhere(world, col, row))
