"""Slow, plain-numpy reference of the interpolation kernels (the tests compare against it)."""

from __future__ import annotations

import numpy as np


def _keys(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Keys (a = -0.5) weights and derivatives, shape (4, n), for offsets -1..2."""
    w = np.stack([
        -0.5 * t**3 + t**2 - 0.5 * t,
        1.5 * t**3 - 2.5 * t**2 + 1,
        -1.5 * t**3 + 2 * t**2 + 0.5 * t,
        0.5 * t**3 - 0.5 * t**2,
    ])
    dw = np.stack([
        -1.5 * t**2 + 2 * t - 0.5,
        4.5 * t**2 - 5 * t,
        -4.5 * t**2 + 4 * t + 0.5,
        1.5 * t**2 - t,
    ])
    return w, dw


def interpolate(north, east, depth, qn, qe, order=1, with_gradient=True):
    """Depth and gradient at (qn, qe): returns (value (n,), grad (n, 2) or None)."""
    qn = np.asarray(qn, float).ravel()
    qe = np.asarray(qe, float).ravel()
    ny, nx = depth.shape
    dn = (north[-1] - north[0]) / (ny - 1)
    de = (east[-1] - east[0]) / (nx - 1)
    fy = (qn - north[0]) / dn
    fx = (qe - east[0]) / de
    inside = (fy >= 0) & (fy <= ny - 1) & (fx >= 0) & (fx <= nx - 1)
    fy = np.where(inside, fy, 0.0)
    fx = np.where(inside, fx, 0.0)
    i = np.minimum(np.floor(fy).astype(int), ny - 2)
    j = np.minimum(np.floor(fx).astype(int), nx - 2)
    ty, tx = fy - i, fx - j

    z00, z01 = depth[i, j], depth[i, j + 1]
    z10, z11 = depth[i + 1, j], depth[i + 1, j + 1]
    value = (1 - ty) * (1 - tx) * z00 + (1 - ty) * tx * z01 + ty * (1 - tx) * z10 + ty * tx * z11
    if order == 1 and not with_gradient:
        return np.where(inside, value, np.nan), None
    g_n = ((1 - tx) * (z10 - z00) + tx * (z11 - z01)) / dn
    g_e = ((1 - ty) * (z01 - z00) + ty * (z11 - z10)) / de

    if order == 3:
        cubic_ok = (i >= 1) & (i <= ny - 3) & (j >= 1) & (j <= nx - 3)
        ii = np.clip(i, 1, ny - 3)
        jj = np.clip(j, 1, nx - 3)
        wy, dwy = _keys(ty)
        wx, dwx = _keys(tx)
        patch = np.stack([
            np.stack([depth[ii - 1 + a, jj - 1 + b] for b in range(4)]) for a in range(4)
        ])  # (4, 4, n)
        c_val = np.einsum("an,bn,abn->n", wy, wx, patch)
        c_gn = np.einsum("an,bn,abn->n", dwy, wx, patch) / dn
        c_ge = np.einsum("an,bn,abn->n", wy, dwx, patch) / de
        use = cubic_ok & np.isfinite(c_val)
        value = np.where(use, c_val, value)
        g_n = np.where(use, c_gn, g_n)
        g_e = np.where(use, c_ge, g_e)

    value = np.where(inside, value, np.nan)
    grad = np.where(inside[:, None], np.stack([g_n, g_e], axis=1), np.nan)
    return value, grad
