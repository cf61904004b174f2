"""The compiled kernels of :mod:`tangraph.filters.likelihood` (its docstring states the model).

One kernel computes every particle's residuals (each particle's grid coordinates once, its
soundings turned by its own angle ``turn``); where the map states its error, another the mean
variance of each of its fields where a cloud puts each sounding (:func:`_field_variance_kernel`);
a third the exponents, the sub-cloud means and every particle's likelihood and tide
(:func:`_update_kernel`).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from tangraph.maps._interp import _FASTMATH, _bilinear


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH, inline="always")
def _footprint_cell(pn, pe, c, s, forward, right, inv_dn, inv_de, ny, nx):
    """The map cell ``(i, j)`` and the fractions ``(ty, tx)`` within it of the footprint ``R(a)
    o`` (``o = (forward, right)``, world metres, turned by the angle of cosine ``c`` and sine
    ``s``) seen from grid coordinates ``(pn, pe)``; ``i = -1`` off the map."""
    fy = pn + (c * forward - s * right) * inv_dn
    fx = pe + (s * forward + c * right) * inv_de
    if not (fy >= 0.0 and fy <= ny - 1 and fx >= 0.0 and fx <= nx - 1):
        return -1, -1, 0.0, 0.0
    i = min(int(fy), ny - 2)
    j = min(int(fx), nx - 2)
    return i, j, fy - i, fx - j


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH, inline="always")
def _particle_sums(depth, pn, pe, offsets, inv_dn, inv_de, c, s, measured, shift):
    """``(sum r, sum r^2)`` of ``r = z - shift - h`` for one particle at grid coordinates
    ``(pn, pe)`` whose soundings' world offsets ``(B, 2)`` (metres) are turned by the angle of
    cosine ``c`` and sine ``s`` (``R(a) o``, ``a`` clockwise from north); NaN if a sounding falls
    off the map or by a NaN cell (``_interp._locate``)."""
    ny, nx = depth.shape
    s1 = 0.0
    s2 = 0.0
    for b in range(offsets.shape[0]):
        i, j, ty, tx = _footprint_cell(pn, pe, c, s, offsets[b, 0], offsets[b, 1], inv_dn, inv_de, ny, nx)
        if i < 0:
            return np.nan, np.nan
        r = measured[b] - shift - _bilinear(depth, i, j, ty, tx)[0]
        s1 += r
        s2 += r * r
    return s1, s2


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH)
def _residual_sums_kernel(
    depth, north0, east0, inv_dn, inv_de, particles, turn, offsets, measured, out
):  # fmt: skip
    """``out[p] = (sum r, sum r^2)`` of ``r = z - h(x_p + R(turn_p) o_b)``, NaN rows where a
    sounding has no map depth."""
    for p in range(particles.shape[0]):
        s1, s2 = _particle_sums(
            depth,
            (particles[p, 0] - north0) * inv_dn,
            (particles[p, 1] - east0) * inv_de,
            offsets,
            inv_dn,
            inv_de,
            np.cos(turn[p]),
            np.sin(turn[p]),
            measured,
            0.0,
        )
        out[p, 0] = s1
        out[p, 1] = s2 if s1 == s1 else np.nan


# A sounding weighs the cloud only where particles holding at least this share of its weight have
# the map under it (MBARI's sub-cloud rule); below it, its weighted spread is numerical noise.
_MIN_SUBCLOUD = 1e-3


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH)
def _residual_kernel(depth, north0, east0, inv_dn, inv_de, particles, turn, offsets, measured, tide, out):
    """``out[b, p] = z_b - tide_p - h(x_p + R(turn_p) o_b)``, NaN where the map has no depth
    (sounding-major, so the per-sounding passes run along memory)."""
    ny, nx = depth.shape
    for p in range(particles.shape[0]):
        pn = (particles[p, 0] - north0) * inv_dn
        pe = (particles[p, 1] - east0) * inv_de
        c = np.cos(turn[p])
        s = np.sin(turn[p])
        for b in range(offsets.shape[0]):
            i, j, ty, tx = _footprint_cell(pn, pe, c, s, offsets[b, 0], offsets[b, 1], inv_dn, inv_de, ny, nx)
            if i < 0:
                out[b, p] = np.nan
                continue
            out[b, p] = measured[b] - tide[p] - _bilinear(depth, i, j, ty, tx)[0]


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH)
def _field_variance_kernel(depth, grids, north0, east0, inv_dn, inv_de, particles, turn, offsets, weights,
                           out):  # fmt: skip
    """Per sounding ``b`` and field ``f`` of the map's error, the ``weights``-mean of the field's
    variance (bilinear in ``grids (ny, nx, F)``) at the footprints the particles put the
    sounding on (``R(turn_p) o_b`` from each), over the particles with a map depth there:
    ``out (B, F)``, 0 where none has."""
    ny, nx = depth.shape
    nf = grids.shape[2]
    out[:, :] = 0.0
    total = np.zeros(offsets.shape[0])
    for p in range(particles.shape[0]):
        w = weights[p]
        if not w > 0.0:
            continue
        pn = (particles[p, 0] - north0) * inv_dn
        pe = (particles[p, 1] - east0) * inv_de
        c = np.cos(turn[p])
        s = np.sin(turn[p])
        for b in range(offsets.shape[0]):
            i, j, ty, tx = _footprint_cell(pn, pe, c, s, offsets[b, 0], offsets[b, 1], inv_dn, inv_de, ny, nx)
            if i < 0:
                continue
            h = _bilinear(depth, i, j, ty, tx)[0]
            if h != h:
                continue
            total[b] += w
            for f in range(nf):
                a = grids[i, j, f] + tx * (grids[i, j + 1, f] - grids[i, j, f])
                d = grids[i + 1, j, f] + tx * (grids[i + 1, j + 1, f] - grids[i + 1, j, f])
                out[b, f] += w * (a + ty * (d - a))
    for b in range(offsets.shape[0]):
        if total[b] > 0.0:
            for f in range(nf):
                out[b, f] /= total[b]


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy")
def _update_kernel(residual, weights, precision, map_variance, exponent, given, tide_var, shape, rate,
                   count_weight, log_likelihood, tide_shift, total_precision, residual_sum, mapped,
                   quadratic, effective):  # fmt: skip
    """Exponents (unless ``given``), sub-cloud means and every particle's likelihood, tide shift,
    summed precision, sum of residuals and count of soundings with the map under it, whitened
    residual sum (at scale 1) and effective count, from the residuals ``(B, N)`` (NaN: no map)
    and the normalised ``weights (N,)``; ``precision (B,)`` is ``1 / v_b``; ``shape > 0``: the
    misfit scale's ``Gamma(shape, rate)`` is integrated out (Student-t), else the scale is 1.
    See the module docstring."""
    nb, n = residual.shape
    s1 = np.zeros(n)
    s2 = np.zeros(n)
    big_l = np.zeros(n)
    missing = np.zeros(n)
    any_map = False
    for b in range(nb):
        total = 0.0
        mean = 0.0
        square = 0.0
        squares = 0.0
        count = 0
        for p in range(n):
            r = residual[b, p]
            w = weights[p]
            if r == r and w > 0.0:
                total += w
                mean += w * r
                square += w * r * r
                squares += w * w
                count += 1
        if total < _MIN_SUBCLOUD:  # (almost) none of the cloud's weight has the map here
            exponent[b] = 0.0
            continue
        any_map = True
        if not given:
            mean /= total
            # (squares / total) / total: total may be tiny (few particles of tiny weight have the map)
            spread = square / total - mean * mean - (1.0 - squares / total / total) * map_variance[b]
            if map_variance[b] <= 0.0:
                exponent[b] = 1.0
            elif spread <= 0.0:
                exponent[b] = 0.0
            else:
                exponent[b] = spread / (spread + 2.0 * map_variance[b])
        lam = exponent[b] * precision[b]
        imputed = lam * square / total  # with a misfit scale: the sub-cloud's mean square
        if count < n and shape <= 0.0:  # some particles have no map here: the sub-cloud's mean likelihood
            top = -np.inf
            for p in range(n):
                r = residual[b, p]
                if r == r and weights[p] > 0.0:
                    top = max(top, -0.5 * lam * r * r)
            acc = 0.0
            for p in range(n):
                r = residual[b, p]
                if r == r and weights[p] > 0.0:
                    acc += weights[p] * np.exp(-0.5 * lam * r * r - top)
            imputed = top + np.log(acc / total)
        for p in range(n):
            r = residual[b, p]
            if r == r:
                s1[p] += lam * r
                s2[p] += lam * r * r
                big_l[p] += lam
                residual_sum[p] += r
                mapped[p] += 1.0
                effective[p] += exponent[b] * count_weight[b]
            else:
                missing[p] += imputed
                if shape > 0.0:
                    effective[p] += exponent[b] * count_weight[b]
    _likelihoods(s1, s2, big_l, missing, effective, any_map, tide_var, shape, rate, log_likelihood,
                 tide_shift, total_precision, quadratic)


@numba.njit(cache=True, nogil=True, fastmath=_FASTMATH, error_model="numpy", inline="always")
def _likelihoods(s1, s2, big_l, missing, effective, any_map, tide_var, shape, rate, log_likelihood,
                 tide_shift, total_precision, quadratic):  # fmt: skip
    """Every particle's likelihood, tide shift, summed precision and whitened residual sum from its
    sums over the soundings (:func:`_update_kernel`)."""
    scale = rate / shape if shape > 0.0 else 1.0
    for p in range(s1.size):
        if not any_map:
            log_likelihood[p] = -np.inf
            tide_shift[p] = 0.0
            total_precision[p] = 0.0
            quadratic[p] = np.nan
            continue
        log_det = 0.0
        tide_shift[p] = 0.0
        total_precision[p] = big_l[p] / scale
        q = s2[p]
        if tide_var > 0.0:  # the tide integrated out at the current scale
            gain = 1.0 / (1.0 / tide_var + big_l[p] / scale)
            q = s2[p] - gain * s1[p] * s1[p] / scale
            log_det = -0.5 * np.log1p(tide_var * big_l[p] / scale)
            tide_shift[p] = gain * s1[p] / scale
        if shape > 0.0:  # missing[p]: the sub-clouds' mean squares of the soundings it has no map under
            q += missing[p]
            half = 0.5 * effective[p]
            log_likelihood[p] = math.lgamma(shape + half) - math.lgamma(shape) + shape * np.log(rate) \
                - (shape + half) * np.log(rate + 0.5 * q) + log_det
        else:  # missing[p]: the sub-clouds' mean log likelihoods
            log_likelihood[p] = -0.5 * q + log_det + missing[p]
        quadratic[p] = q
