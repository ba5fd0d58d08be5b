"""The terrain model.

The cell grid, the DEM (per-cell mean, variance, count; holes filled from a coarse DEM), the
bilinear surface and its kernel, the min/max pyramid the ray caster walks, DEM tile import
and point clouds. May import ``core.geo`` and ``core.errors``.
"""
