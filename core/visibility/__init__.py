"""Visibility.

Viewsheds and coverage through trees and buildings (numba sweep kernel and its numpy
reference; over a tiled DEM, exact viewsheds and coverage one Dask task per output tile,
``tiled_viewshed``), target-aware sight lines, why a track has a gap, and hand-off
prediction between cameras. May import ``core.geolocation``, ``core.camera``,
``core.raycast``, ``core.terrain``, ``core.geo``, ``core.tracking`` and ``core.errors``.
"""
