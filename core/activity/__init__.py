"""Activity detectors over tracks.

Loitering, rendezvous, convoys, zone entries and exits, with a numba polyline kernel and a
plain reference twin (:mod:`.reference`). May import ``core.tracking``, ``core.geo`` and
``core.errors``.
"""
