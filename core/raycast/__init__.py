"""Ray casting against the DEM surface.

The caster API (:mod:`.cast`), its numba kernels (the ``_kernels`` modules, arrays only),
the per-origin angular index for camera rays, and the plain-numpy reference twin
(:mod:`.reference`) that the tests compare against. May import ``core.terrain``,
``core.geo`` and ``core.errors``.
"""
