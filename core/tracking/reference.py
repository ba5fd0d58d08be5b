"""Plain-numpy twins of the tracking kernels, for the tests.

Each has the same arguments and results as its kernel, computed with whole-array numpy
operations (the vectorised forms the kernels replaced): :mod:`.kalman_kernels` (predict,
update, RTS smoothing), :mod:`.fusion_kernels` (pair screening, triangulation covariance)
and :mod:`.hypothesiser_kernels` (gating).
"""

from __future__ import annotations

import numpy as np

from .hypothesiser import mahalanobis2

__all__ = [
    "gate_reference",
    "predict_reference",
    "rts_positions_reference",
    "screen_pairs_reference",
    "smoother_gain_reference",
    "triangulation_cov_reference",
    "update_reference",
]


_H = np.hstack([np.eye(2), np.zeros((2, 2))])


def predict_reference(x, p, f, q):
    """:func:`~demtrack.core.tracking.kalman_kernels.predict_kernel` in numpy."""
    p_new = f @ p @ f.T + q
    return f @ x, 0.5 * (p_new + p_new.T)


def update_reference(x, p, z_xy, r):
    """:func:`~demtrack.core.tracking.kalman_kernels.update_kernel` in numpy."""
    s = p[:2, :2] + r
    det = s[0, 0] * s[1, 1] - s[0, 1] * s[1, 0]
    s_inv = np.array([[s[1, 1], -s[0, 1]], [-s[1, 0], s[0, 0]]]) / det
    k = (s_inv @ p[:2, :]).T
    x_new = x + k @ (z_xy - x[:2])
    ikh = np.eye(4) - k @ _H
    p_new = ikh @ p @ ikh.T + k @ r @ k.T
    return x_new, 0.5 * (p_new + p_new.T)


def smoother_gain_reference(p_k, f, q):
    """:func:`~demtrack.core.tracking.kalman_kernels.smoother_gain_kernel` in numpy."""
    p_pred = f @ p_k @ f.T + q
    return np.linalg.solve(p_pred, f @ p_k).T


def rts_positions_reference(xs, fs, gains):
    """:func:`~demtrack.core.tracking.kalman_kernels.rts_positions_kernel` in numpy."""
    s = xs[-1]
    out = [s[:2].copy()]
    for k in range(len(xs) - 2, -1, -1):
        s = xs[k] + gains[k] @ (s - fs[k] @ xs[k])
        out.append(s[:2].copy())
    return np.array(out[::-1])


# ---------------------------------------------------------------- fusion


def _padded_d2(hits_xy: np.ndarray, hits_cov: np.ndarray, p_enu: np.ndarray) -> np.ndarray:
    """Smallest squared Mahalanobis distance of ``p_enu`` (na, nb, 3) to NaN-padded hits."""
    d = hits_xy - p_enu[:, :, None, :2]
    a, b, c = hits_cov[..., 0, 0], hits_cov[..., 0, 1], hits_cov[..., 1, 1]
    det = a * c - b * b
    d2 = (c * d[..., 0] ** 2 - 2 * b * d[..., 0] * d[..., 1] + a * d[..., 1] ** 2) / det
    return np.min(np.where(np.isnan(d2), np.inf, d2), axis=-1)


def screen_pairs_reference(
    oa, da, ta, ca, hxa, sga, cva, ob, db, tb, cb, hxb, sgb, cvb, window_s, min_sin, max_miss, gate
):
    """:func:`~demtrack.core.tracking.fusion_kernels.screen_pairs_kernel` in numpy."""
    same = (ca[:, None] == cb[None, :]) & (np.abs(ta[:, None] - tb[None, :]) <= window_s)
    b = da @ db.T
    denom = 1.0 - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        w0 = oa[:, None, :] - ob[None, :, :]
        d = np.einsum("ik,ijk->ij", da, w0)
        e = np.einsum("jk,ijk->ij", db, w0)
        s = (b * e - d) / denom
        t = (e - b * d) / denom
        pa = oa[:, None, :] + s[..., None] * da[:, None, :]
        pb = ob[None, :, :] + t[..., None] * db[None, :, :]
        p = 0.5 * (pa + pb)
        miss = np.linalg.norm(pa - pb, axis=-1)
        sin_angle = np.sin(np.arccos(np.clip(b, -1.0, 1.0)))
        dist_a = np.linalg.norm(hxa[:, None, :, :] - p[:, :, None, :2], axis=-1)
        dist_b = np.linalg.norm(hxb[None, :, :, :] - p[:, :, None, :2], axis=-1)
        near_a = np.nanmax(gate * sga[:, None, :] + 1.0 - dist_a, axis=-1, initial=-np.inf)
        near_b = np.nanmax(gate * sgb[None, :, :] + 1.0 - dist_b, axis=-1, initial=-np.inf)
        slack = np.stack(
            [denom - 1e-12, sin_angle - min_sin, max_miss - miss, s, t, near_a, near_b]
        )
        d2 = _padded_d2(hxa[:, None], cva[:, None], p) + _padded_d2(hxb[None], cvb[None], p)
    worst = np.where(np.isnan(slack), -np.inf, slack).min(axis=0)
    return same, worst, d2, p, miss, s, t, sin_angle


def triangulation_cov_reference(
    p, miss, sin_angle, range_a, range_b, ga, gb, hxa, cva, hxb, cvb, ray_sigma
):
    """:func:`~demtrack.core.tracking.fusion_kernels.triangulation_cov_kernel` in numpy."""
    sa = ray_sigma * range_a
    sb = ray_sigma * range_b
    worst = np.sqrt(0.5 * (sa * sa + sb * sb)) / sin_angle
    info = np.eye(2)[None] / (worst * worst)[:, None, None]
    for g, hits_xy, hits_cov, s in ((ga, hxa, cva, sa), (gb, hxb, cvb, sb)):
        norm = np.hypot(g[:, 0], g[:, 1])
        vertical = norm < 1e-9
        n = np.where(
            vertical[:, None],
            np.array([1.0, 0.0]),
            np.stack([-g[:, 1], g[:, 0]], axis=1) / np.where(vertical, 1.0, norm)[:, None],
        )
        d2 = np.sum((hits_xy - p[:, None, :2]) ** 2, axis=2)
        j = np.argmin(np.where(np.isnan(d2), np.inf, d2), axis=1)
        c = hits_cov[np.arange(len(p)), j]
        var = np.einsum("ki,kij,kj->k", n, c, n)
        s = np.maximum(s, np.sqrt(var))
        nn = n[:, :, None] * n[:, None, :]
        info += np.where(vertical[:, None, None], np.eye(2)[None], nn) / (s * s)[:, None, None]
    cov = np.linalg.inv(info)
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2))
    cov += (np.maximum(0.5 * miss, 0.05) ** 2)[:, None, None] * np.eye(2)[None]
    half_tr = 0.5 * (cov[:, 0, 0] + cov[:, 1, 1])
    half_diff = 0.5 * (cov[:, 0, 0] - cov[:, 1, 1])
    sigma = np.sqrt(half_tr + np.hypot(half_diff, cov[:, 0, 1]))
    return cov, sigma


# ---------------------------------------------------------------- gating


def gate_reference(
    means_xy: np.ndarray,
    covs_xy: np.ndarray,
    z_xy: np.ndarray,
    cov: np.ndarray,
    slots: np.ndarray,
    allowed: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`gate_kernel` in numpy (batched :func:`~.hypothesiser.mahalanobis2`)."""
    n_tracks = means_xy.shape[0]
    s = covs_xy[:, None, :, :] + cov[None, :, :, :]
    nu = z_xy[None, :, :] - means_xy[:, None, :]
    d2 = mahalanobis2(s, nu)
    d2 = np.concatenate([d2, np.full((n_tracks, 1), np.inf)], axis=1)[:, slots]
    best = np.argmin(d2, axis=2)
    d2_best = np.take_along_axis(d2, best[..., None], axis=2)[..., 0]
    return np.where(allowed, best, -1), np.where(allowed, d2_best, np.inf)
