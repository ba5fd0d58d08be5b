"""Ray casting against the DEM surface.

The caster API (:mod:`.cast`), its numba kernels (the ``_kernels`` modules, arrays only),
the per-origin angular index for camera rays, and the plain-numpy reference twin
(:mod:`.reference`) that the tests compare against; over a tiled DEM larger than memory, the
same walk block by block through an LRU of decoded blocks (:mod:`.tiled_cast`,
:mod:`.tile_cache`). May import ``core.terrain``, ``core.geo`` and ``core.errors``.
"""
