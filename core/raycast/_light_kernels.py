"""A quick-to-compile twin of the pyramid-walk casting kernel (``core.raycast._kernels``).

``cast_kernel`` runs the whole pyramid walk (``_walk``, inlined) inside a numba parallel
loop; numba's parallel-loop passes over that body are most of a cold start: about 19 s
of CPU to compile ``cast_kernel`` alone, plus about 15 s for the all-hits re-walk.
:func:`cast_kernel_light` is the same loop on one thread: the same walk and the same
answers bit for bit, in well under half the compile time. It releases the GIL, so
callers may cast on several threads at once (the sample-site build renders two cameras
at a time). ``core.raycast.cast`` uses it while
"light kernels" are on (:func:`demtrack.core.raycast.cast.use_light_kernels`): the sample-site
build's renders and a cold ``demtrack demo`` until its warm-up has the fast kernels ready.
Rays with more hits than the first pass keeps are cast again by the same kernel with room
for all their hits (``core.raycast.cast``), so no re-walk kernel has to compile either.
"""

from __future__ import annotations

from numba import njit

from ._walk_kernels import HIT, MISS, _walk, prepare_row

__all__ = ["cast_kernel_light"]

# The walk as a function of its own, called once per ray (``cast_kernel`` inlines it):
# the call costs nothing measurable (the sample-site renders cast as fast) and the cold
# compile is about a fifth shorter (numba no longer copies and re-types the walk's body
# inside the loop's). Same function, same options but the inlining: the same bits, and
# the same entry in numba's cache as any standalone compile of ``_walk``.
_walk_call = njit(cache=True, error_model="numpy", nogil=True)(_walk.py_func)


@njit(cache=True, error_model="numpy", nogil=True)
def cast_kernel_light(
    elev,
    nodes,
    lvl_off,
    lvl_shape,
    x_min,
    y_max,
    cell,
    z_min,
    z_max,
    margin,
    origins,
    directions,
    max_range,
    first_only,
    max_hits,
    nthreads,
    buf,
    counts,
    status,
    crossed,
    truncated,
):  # pragma: no cover - numba
    """``raycast_kernels.cast_kernel`` (same arguments and results) on one thread.

    ``nthreads`` is accepted for the same signature and ignored.
    """
    n = origins.shape[0]
    cap = buf.shape[1]
    hits = buf.reshape(buf.size)
    for i in range(n):
        st, gx0, gy0, kx, ky, uz, t_a, t_end = prepare_row(
            elev, nodes, lvl_off, lvl_shape, x_min, y_max, cell, z_min, z_max, margin,
            origins, directions, max_range, i,
        )  # fmt: skip
        crossed[i] = False
        truncated[i] = False
        counts[i] = 0
        if st != HIT:
            status[i] = st
            continue
        cnt, cr = _walk_call(
            elev,
            nodes,
            lvl_off,
            lvl_shape,
            margin,
            gx0,
            gy0,
            origins[i, 2],
            kx,
            ky,
            uz,
            t_a,
            t_end,
            hits,
            i * cap,
            cap,
            max_hits,
            first_only,
        )
        crossed[i] = cr
        if cnt > max_hits:
            truncated[i] = True
            cnt = max_hits
        counts[i] = cnt
        status[i] = HIT if cnt > 0 else MISS
