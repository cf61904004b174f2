"""The ``direct`` path of the criterion search (:func:`tangraph.matching.search.criterion_sums`): numba
kernels over candidates x soundings. When the candidate steps are whole map cells, a sounding's
bilinear weights are the same at every candidate and the kernel runs unit-stride (SIMD) loops along
candidate rows; otherwise it evaluates every bilinear depth."""

from __future__ import annotations

import numba
import numpy as np

# fastmath without "nnan"/"ninf": NaN marks no-data and must survive.
_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}
_jit = numba.njit(cache=True, nogil=True, fastmath=_FASTMATH)
_inline = numba.njit(cache=True, nogil=True, fastmath=_FASTMATH, inline="always")

# -- kernels -------------------------------------------------------------------------------------
# Both kernels walk tiles of candidate rows. For each block of _BLOCK soundings and each row of the
# tile they write the block's residuals along the row (NaN where a sounding has no depth), then add
# the block to the row's accumulators (soundings without a depth, sum d, d^2, d z, |d|) in two
# unit-stride loops that vectorise (split so that each stays within LLVM's limit of runtime alias
# checks). A tile's accumulators stay in cache while the block's map rows are reused.
_BLOCK = 8
_TILE_VALUES = 4096  # candidate rows per tile x candidate columns


@_inline
def _flush(block, zb, k, acc):
    """Add residual rows ``block[:k]`` (measured depths ``zb``) to ``acc (5, ne)``."""
    block[k:] = 0.0
    zb[k:] = 0.0
    bad, s1, s2, s3, s4 = acc[0], acc[1], acc[2], acc[3], acc[4]
    for c in range(acc.shape[1]):
        t1 = t2 = t3 = 0.0
        for q in range(_BLOCK):
            d = block[q, c]
            t1 += d
            t2 += d * d
            t3 += d * zb[q]
        s1[c] += t1
        s2[c] += t2
        s3[c] += t3
    for c in range(acc.shape[1]):
        t0 = t4 = 0.0
        for q in range(_BLOCK):
            d = block[q, c]
            t0 += 0.0 if d == d else 1.0
            t4 += abs(d)
        bad[c] += t0
        s4[c] += t4


@_inline
def _shift_row(depth, i, js, mj, t_y, t_x, zs, row):
    """Residuals along a candidate row of a sounding in cells ``(i, js + c mj)``."""
    ne, (ny, nx) = row.size, depth.shape
    c_lo = min(ne, 0 if js >= 0 else (mj - 1 - js) // mj)
    c_hi = min(ne - 1, (nx - 2 - js) // mj) if 0 <= i <= ny - 2 else -1
    row[:c_lo] = np.nan
    row[max(c_hi + 1, c_lo) :] = np.nan
    if c_hi < c_lo:
        return
    row0, row1 = depth[i], depth[i + 1]
    if mj == 1:  # unit stride, written apart so that it vectorises
        r0, r1, out = row0[js + c_lo : js + c_hi + 2], row1[js + c_lo : js + c_hi + 2], row[c_lo : c_hi + 1]
        for c in range(out.size):
            a = r0[c] + t_x * (r0[c + 1] - r0[c])
            b = r1[c] + t_x * (r1[c + 1] - r1[c])
            out[c] = a + t_y * (b - a) - zs
        return
    for c in range(c_lo, c_hi + 1):
        j = js + c * mj
        a = row0[j] + t_x * (row0[j + 1] - row0[j])
        b = row1[j] + t_x * (row1[j + 1] - row1[j])
        row[c] = a + t_y * (b - a) - zs


@_jit
def _shift_kernel(depth, i0, j0, ty, tx, z, mi, mj, out):
    """Whole-cell shifts: sounding s at candidate (r, c) lies in cell (i0 + r mi, j0 + c mj) with
    fractions (ty, tx). ``out (nn, 5, ne)`` gets count, sum d, d^2, d z, |d|."""
    nn, _, ne = out.shape
    ns = z.size
    block, zb = np.empty((_BLOCK, ne)), np.empty(_BLOCK)
    tile = max(1, _TILE_VALUES // ne)
    for r0 in range(0, nn, tile):
        for s0 in range(0, ns, _BLOCK):
            k = min(_BLOCK, ns - s0)
            for r in range(r0, min(r0 + tile, nn)):
                for q in range(k):
                    s = s0 + q
                    _shift_row(depth, i0[s] + r * mi, j0[s], mj, ty[s], tx[s], z[s], block[q])
                    zb[q] = z[s]
                _flush(block, zb, k, out[r])
    out[:, 0, :] = ns - out[:, 0, :]


@_jit
def _general_kernel(depth, north0, east0, inv_dn, inv_de, cand_n, cand_e, off_n, off_e, z, out):
    """Any grid: bilinear depths per (candidate, sounding) by ``depth_at``'s rules (map rows are
    blended first, then columns). ``off_n, off_e (nh, N)``; ``out (nh, nn, 5, ne)``."""
    ny, nx = depth.shape
    nh, ns = off_n.shape
    nn, ne = cand_n.size, cand_e.size
    block, zb = np.empty((_BLOCK, ne)), np.empty(_BLOCK)
    blend = np.full(nx + 1, np.nan)  # blend[nx] = NaN: the column of points off the map
    cols, fracs = np.empty((_BLOCK, ne), dtype=np.int64), np.empty((_BLOCK, ne))
    span = np.empty((_BLOCK, 2), dtype=np.int64)
    tile = max(1, _TILE_VALUES // ne)
    for h in range(nh):
        for r0 in range(0, nn, tile):
            for s0 in range(0, ns, _BLOCK):
                k = min(_BLOCK, ns - s0)
                for q in range(k):  # column and fraction of each sounding at each candidate column
                    span[q] = nx - 1, 0
                    for c in range(ne):
                        fx = (cand_e[c] + off_e[h, s0 + q] - east0) * inv_de
                        inside = fx >= 0.0 and fx <= nx - 1
                        j = min(int(fx), nx - 2) if inside else nx - 1
                        cols[q, c], fracs[q, c] = j, fx - j if inside else 0.0
                        if inside:
                            span[q] = min(span[q, 0], j), max(span[q, 1], j + 1)
                    zb[q] = z[s0 + q]
                for r in range(r0, min(r0 + tile, nn)):
                    for q in range(k):
                        fy = (cand_n[r] + off_n[h, s0 + q] - north0) * inv_dn
                        if not (fy >= 0.0 and fy <= ny - 1):
                            block[q, :] = np.nan
                            continue
                        i = min(int(fy), ny - 2)
                        t_y = fy - i
                        for c in range(span[q, 0], span[q, 1] + 1):
                            blend[c] = depth[i, c] + t_y * (depth[i + 1, c] - depth[i, c])
                        js, ts, row = cols[q], fracs[q], block[q]
                        for c in range(ne):
                            row[c] = blend[js[c]] + ts[c] * (blend[js[c] + 1] - blend[js[c]]) - zb[q]
                    _flush(block, zb, k, out[h, r])
    out[:, :, 0, :] = ns - out[:, :, 0, :]


def _direct_sums(bathymetry, grid, layouts, off_n, off_e, z, mi, mj, whole_cell, sum_z, sum_z2):
    """Count and sums (``sum_d`` ... ``sum_hz``) by the kernels: whole-cell shifts per heading
    (``layouts`` from :func:`tangraph.matching.search_fft._layout`) or the general kernel."""
    nh, nn, ne = grid.shape
    dn, de = bathymetry.cell_size
    acc = np.zeros((nh, nn, 5, ne))
    if whole_cell:
        for h, (i0, j0, ty, tx) in enumerate(layouts):
            _shift_kernel(bathymetry.depth, i0, j0, ty, tx, z, mi, mj, acc[h])
    else:
        _general_kernel(bathymetry.depth, bathymetry.north[0], bathymetry.east[0], 1.0 / dn, 1.0 / de,
                        grid.north, grid.east, off_n, off_e, z, acc)  # fmt: skip
    count = acc[:, :, 0].astype(np.int64)
    sum_d, sum_d2, sum_dz = acc[:, :, 1], acc[:, :, 2], acc[:, :, 3]
    sums = {"sum_d": sum_d, "sum_d2": sum_d2, "sum_abs": acc[:, :, 4], "sum_h": sum_d + sum_z,
            "sum_h2": sum_d2 + 2.0 * sum_dz + sum_z2, "sum_hz": sum_dz + sum_z2}  # fmt: skip
    return count, sums
