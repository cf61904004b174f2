"""The compiled kernels behind every "depth of the map at many points" query.

One loop over query points, bilinear or Keys bicubic (a = -0.5) on a regular grid, and the
analytic gradient of the same interpolant. The pure-numpy reference lives in the tests
(``tests/maps/reference.py``) and the two are compared there.

Rules (documented in ``BathymetryMap.depth_at``):
- a point outside the rectangle spanned by the outer cell centres gets NaN (never clamped);
- bilinear: NaN if any of the 4 surrounding cells is NaN;
- bicubic: uses the 4 x 4 neighbourhood; where that leaves the grid or holds a NaN, the point
  falls back to bilinear (so the valid area is the same for both orders).

The loops are split by order and by "with gradient" so that the common case (bilinear depth)
is a tight loop; the shared pieces are inlined helpers.
"""

from __future__ import annotations

import numba
import numpy as np

# fastmath without "nnan"/"ninf": NaN marks no-data and must survive.
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
_jit = numba.njit(cache=True, nogil=True, fastmath=_FASTMATH)
_inline = numba.njit(cache=True, nogil=True, fastmath=_FASTMATH, inline="always")


@_inline
def _locate(depth, north0, east0, inv_dn, inv_de, qn, qe):
    """Cell (i, j) and fractions (ty, tx) of one point; ok False off the grid (or NaN query)."""
    ny, nx = depth.shape
    fy = (qn - north0) * inv_dn
    fx = (qe - east0) * inv_de
    if not (fy >= 0.0 and fy <= ny - 1 and fx >= 0.0 and fx <= nx - 1):
        return False, 0, 0, 0.0, 0.0
    i = min(int(fy), ny - 2)
    j = min(int(fx), nx - 2)
    return True, i, j, fy - i, fx - j


@_inline
def _bilinear(depth, i, j, ty, tx):
    z00 = depth[i, j]
    z01 = depth[i, j + 1]
    z10 = depth[i + 1, j]
    z11 = depth[i + 1, j + 1]
    a = z00 + tx * (z01 - z00)
    b = z10 + tx * (z11 - z10)
    value = a + ty * (b - a)
    d_ty = (1.0 - tx) * (z10 - z00) + tx * (z11 - z01)
    d_tx = (1.0 - ty) * (z01 - z00) + ty * (z11 - z10)
    return value, d_ty, d_tx


@_inline
def _keys(t):
    """Keys cubic-convolution weights (a = -0.5) for offsets -1, 0, 1, 2 and their derivatives."""
    t2 = t * t
    t3 = t2 * t
    w = (-0.5 * t3 + t2 - 0.5 * t, 1.5 * t3 - 2.5 * t2 + 1.0, -1.5 * t3 + 2.0 * t2 + 0.5 * t,
         0.5 * t3 - 0.5 * t2)
    dw = (-1.5 * t2 + 2.0 * t - 0.5, 4.5 * t2 - 5.0 * t, -4.5 * t2 + 4.0 * t + 0.5, 1.5 * t2 - t)
    return w, dw


@_inline
def _bicubic(depth, i, j, ty, tx):
    """Value and derivatives (per cell) of the bicubic interpolant; NaN if any cell is NaN."""
    wy, dwy = _keys(ty)
    wx, dwx = _keys(tx)
    value = 0.0
    d_ty = 0.0
    d_tx = 0.0
    for a in range(4):
        r = i - 1 + a
        row = 0.0
        drow = 0.0
        for b in range(4):
            z = depth[r, j - 1 + b]
            row += wx[b] * z
            drow += dwx[b] * z
        value += wy[a] * row
        d_ty += dwy[a] * row
        d_tx += wy[a] * drow
    return value, d_ty, d_tx


@_inline
def _evaluate(depth, i, j, ty, tx, order):
    ny, nx = depth.shape
    if order == 3 and i >= 1 and i <= ny - 3 and j >= 1 and j <= nx - 3:
        value, d_ty, d_tx = _bicubic(depth, i, j, ty, tx)
        if value == value:  # no NaN among the 16 cells
            return value, d_ty, d_tx
    return _bilinear(depth, i, j, ty, tx)


@_jit
def depth_kernel(depth, north0, east0, inv_dn, inv_de, qn, qe, order, out):
    """``out[k]`` = interpolated depth at ``(qn[k], qe[k])``; ``order`` 1 or 3."""
    ny, nx = depth.shape
    if order == 1:  # the hot path, written out in full
        for k in range(qn.size):
            fy = (qn[k] - north0) * inv_dn
            fx = (qe[k] - east0) * inv_de
            if not (fy >= 0.0 and fy <= ny - 1 and fx >= 0.0 and fx <= nx - 1):
                out[k] = np.nan
                continue
            i = min(int(fy), ny - 2)
            j = min(int(fx), nx - 2)
            ty = fy - i
            tx = fx - j
            a = depth[i, j] + tx * (depth[i, j + 1] - depth[i, j])
            b = depth[i + 1, j] + tx * (depth[i + 1, j + 1] - depth[i + 1, j])
            out[k] = a + ty * (b - a)
    else:
        for k in range(qn.size):
            ok, i, j, ty, tx = _locate(depth, north0, east0, inv_dn, inv_de, qn[k], qe[k])
            if ok:
                out[k] = _evaluate(depth, i, j, ty, tx, 3)[0]
            else:
                out[k] = np.nan


@_jit
def gradient_kernel(depth, north0, east0, inv_dn, inv_de, qn, qe, order, out, grad):
    """As :func:`depth_kernel`, and ``grad[k] = (d depth/d north, d depth/d east)``."""
    for k in range(qn.size):
        ok, i, j, ty, tx = _locate(depth, north0, east0, inv_dn, inv_de, qn[k], qe[k])
        if ok:
            value, d_ty, d_tx = _evaluate(depth, i, j, ty, tx, order)
            out[k] = value
            grad[k, 0] = d_ty * inv_dn
            grad[k, 1] = d_tx * inv_de
        else:
            out[k] = np.nan
            grad[k, 0] = np.nan
            grad[k, 1] = np.nan


def box_mean(layer: np.ndarray, kn: int, ke: int) -> np.ndarray:
    """Mean of the data cells in a ``kn`` x ``ke`` box around each cell (NaN stays NaN)."""
    from scipy.ndimage import uniform_filter

    valid = np.isfinite(layer)
    total = uniform_filter(np.where(valid, layer, 0.0), size=(kn, ke), mode="nearest")
    weight = uniform_filter(valid.astype(float), size=(kn, ke), mode="nearest")
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(valid, total / weight, np.nan)
