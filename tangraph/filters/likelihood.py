"""The one terrain likelihood every particle filter shares, in compiled kernels.

The model is :mod:`tangraph.sensors.terrain`'s: sounding ``b`` of a ping measures
``z_b = h(x + o_b) + tide + e_b`` with ``h`` the map's bilinear depth (the rules of
:mod:`tangraph.maps._interp`) and ``e_b`` of variance ``v_b`` (the sounding's noise plus the map
error it shares with the survey's other soundings: the row-sum bound). For particle ``p`` with
residuals ``r_pb = z_b - m_p - h(x_p + R(turn_p) o_b)`` (``m_p`` its tide mean) and the
soundings' precisions ``l_b = a_b / v_b``:

- **known tide** (``tide_var = 0``): ``log p = -1/2 sum_b l_b r_pb^2``;
- **Gaussian tide posterior** ``N(m_p, v)``: the predictive density of the ping,
  ``log p = -1/2 (S2 - S1^2 / (1/v + L)) - 1/2 log(1 + v L)`` with ``S1 = sum l r``,
  ``S2 = sum l r^2``, ``L = sum l`` over the particle's soundings; its posterior tide mean is
  ``m_p + S1 / (1/v + L)``;
- **no map, no evidence**: a sounding with no map depth under a particle (off the grid, or by a
  NaN cell) is missing information for that particle, not evidence against it: it is given the
  weighted mean likelihood ``log sum_q w_q exp(-l_b r_qb^2 / 2) / sum_q w_q`` of the particles
  that do have the map under it (MBARI's sub-cloud rule); a sounding whose sub-cloud holds less
  than 0.1 % of the cloud's weight is left out for all (as MBARI's filter does). Only a ping no
  sounding of which has the map under the cloud gives ``-inf`` everywhere (:class:`OffMap`);
- **terrain information gating**: ``a_b`` in [0, 1] is MBARI's modified weighting
  (:func:`tangraph.sensors.information_exponent`) from how far the cloud's predicted depths for
  sounding ``b`` spread beyond the map's error there (1 with a perfect map); computed once per
  ping from the weighted cloud and passed back in for the same ping's later evaluations
  (tempering stages, IPF children) so that their likelihood ratios are of one function.

- **a misfit scale of its own** (:mod:`tangraph.sensors.misfit`): given a ``Gamma(shape, rate)``
  on the precision factor shared by the ping's soundings, the quadratic ``Q`` above (the tide
  integrated out at the scale's estimate ``rate / shape``) enters the Student-t
  ``lgamma(shape + n/2) - lgamma(shape) + shape log(rate) - (shape + n/2) log(rate + Q/2)``
  with ``n`` the particle's summed expected squares ``a_b c_b``; a sounding without a map depth
  under a particle adds to its ``Q`` the sub-cloud's weighted mean of ``a_b r^2 / v_b`` and to its
  ``n`` its ``a_b c_b`` (so every particle's Student-t has the same count, and none gains by having
  no map under a sounding).

Constants shared by all particles are dropped: weights are normalised. One kernel computes
every particle's residuals (each particle's grid coordinates once, its soundings turned by its
own angle ``turn``: a filter's particle turns them by minus its heading error), a second the
exponents, the sub-cloud means and every particle's likelihood and tide.
"""

from __future__ import annotations

import dataclasses
import math

import numba
import numpy as np

from tangraph.errors import TangraphError
from tangraph.maps._interp import _FASTMATH, _bilinear
from tangraph.maps.grid import BathymetryMap

__all__ = [
    "FilterDivergence",
    "OffMap",
    "PingLikelihood",
    "TerrainLikelihood",
    "effective_sample_size",
    "log_normalise",
]


class FilterDivergence(TangraphError):
    """Every particle has zero likelihood: the filter has lost the vehicle."""


class OffMap(FilterDivergence):
    """No sounding of a ping has the map under any particle: the ping says nothing about where
    the vehicle is (it is not evidence against any particle)."""


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
        on = c * offsets[b, 0] - s * offsets[b, 1]
        oe = s * offsets[b, 0] + c * offsets[b, 1]
        fy = pn + on * inv_dn
        fx = pe + oe * inv_de
        if not (fy >= 0.0 and fy <= ny - 1 and fx >= 0.0 and fx <= nx - 1):
            return np.nan, np.nan
        i = min(int(fy), ny - 2)
        j = min(int(fx), nx - 2)
        r = measured[b] - shift - _bilinear(depth, i, j, fy - i, fx - j)[0]
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
            fy = pn + (c * offsets[b, 0] - s * offsets[b, 1]) * inv_dn
            fx = pe + (s * offsets[b, 0] + c * offsets[b, 1]) * inv_de
            if not (fy >= 0.0 and fy <= ny - 1 and fx >= 0.0 and fx <= nx - 1):
                out[b, p] = np.nan
                continue
            i = min(int(fy), ny - 2)
            j = min(int(fx), nx - 2)
            out[b, p] = measured[b] - tide[p] - _bilinear(depth, i, j, fy - i, fx - j)[0]


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


@dataclasses.dataclass(frozen=True, eq=False)
class PingLikelihood:
    """The terrain likelihood of one ping for every particle (from
    :meth:`TerrainLikelihood.ping_update`): ``log_likelihood (N,)`` (up to a constant; ``-inf``
    everywhere when no sounding has the map under any particle), the posterior tide means
    ``tide (N,)`` and their shared variance ``tide_var``, the mean predicted depth ``predicted
    (N,)`` (the ping's mean measured depth less the particle's mean residual; NaN for a particle
    with the map under none of its soundings), the exponents ``exponent (B,)`` and the share of
    soundings with the map under each particle, ``mapped (N,)``."""

    log_likelihood: np.ndarray
    tide: np.ndarray
    tide_var: float
    predicted: np.ndarray
    exponent: np.ndarray
    mapped: np.ndarray
    quadratic: np.ndarray | None = None
    count: np.ndarray | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class TerrainLikelihood:
    """The terrain likelihood on a map, with a default sounding std ``sigma`` (m) and known
    ``tide`` for the calls that give no per-sounding variances (see the module docstring)."""

    bathymetry: BathymetryMap
    sigma: float
    tide: float = 0.0

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise TangraphError(f"TerrainLikelihood: sigma must be positive, got {self.sigma!r}")

    def log_likelihood(self, particles, offsets, depths, turn=None) -> np.ndarray:
        """Log-likelihood (N,) of particles (N, 2) for soundings at ``offsets`` (B, 2) (world
        north/east from the vehicle) with measured ``depths`` (B,), of std ``sigma`` around the
        map depth plus ``tide``, all particles weighted equally; NaN depths are skipped.

        ``-1/2 sum_b (z_b - tide - h(x + R(turn) o_b))^2 / sigma^2`` where every sounding has a
        map depth; a sounding without one takes the mean likelihood of the particles that have
        one (module docstring). ``turn (N,)`` (rad, clockwise from north; None: 0) turns each
        particle's offsets about the vehicle.
        """
        particles = np.asarray(particles, dtype=np.float64)
        tide = np.full(particles.shape[0] if particles.ndim else 0, float(self.tide))
        return self.tide_update(particles, offsets, depths, tide, 0.0, turn=turn)[0]

    def _checked(self, particles, offsets, depths, turn, keep_nan=False) -> tuple[np.ndarray, ...]:
        particles = np.ascontiguousarray(particles, dtype=np.float64)
        offsets = np.ascontiguousarray(offsets, dtype=np.float64)
        depths = np.asarray(depths, dtype=np.float64)
        if particles.ndim != 2 or particles.shape[1] != 2:
            raise TangraphError(f"particles must have shape (N, 2), got {particles.shape}")
        if offsets.ndim != 2 or offsets.shape[1] != 2 or depths.shape != (offsets.shape[0],):
            raise TangraphError(
                f"offsets (B, 2) and depths (B,) do not match: {offsets.shape}, {depths.shape}"
            )
        n = particles.shape[0]
        if turn is None:
            turn = np.zeros(n)
        turn = np.ascontiguousarray(turn, dtype=np.float64)
        if turn.shape != (n,):
            raise TangraphError(f"turn must have shape ({n},) as particles, got {turn.shape}")
        keep = np.isfinite(depths)
        if not keep.all() and not keep_nan:
            offsets, depths = np.ascontiguousarray(offsets[keep]), depths[keep]
        return particles, offsets, np.ascontiguousarray(depths), turn

    def residual_sums(self, particles, offsets, depths, turn=None) -> np.ndarray:
        """``(N, 2)``: per particle the sum and the sum of squares of the residuals
        ``r = z - h(x + R(turn) o)`` (measured minus map depth, ``tide`` not removed) of the
        finite soundings; NaN rows for particles with a sounding off the map or by a NaN cell.
        ``turn (N,)``: see :meth:`log_likelihood`.
        """
        particles, offsets, depths, turn = self._checked(particles, offsets, depths, turn)
        out = np.empty((particles.shape[0], 2))
        n0, e0, dn, de = self.bathymetry._grid  # type: ignore[attr-defined]
        _residual_sums_kernel(
            self.bathymetry.depth, n0, e0, 1.0 / dn, 1.0 / de, particles, turn, offsets, depths, out
        )
        return out

    def residuals(self, particles, offsets, depths, tide, *, turn=None) -> np.ndarray:
        """``(B, N)`` residuals ``z_b - tide_p - h(x_p + R(turn_p) o_b)`` (NaN: no map depth, or
        a NaN depth), one compiled pass; sounding-major."""
        particles, offsets, depths, turn = self._checked(particles, offsets, depths, turn, keep_nan=True)
        tide = np.ascontiguousarray(tide, dtype=np.float64)
        if tide.shape != (particles.shape[0],):
            raise TangraphError(f"tide must have shape ({particles.shape[0]},) as particles, "
                                f"got {tide.shape}")
        out = np.empty((offsets.shape[0], particles.shape[0]))
        n0, e0, dn, de = self.bathymetry._grid  # type: ignore[attr-defined]
        _residual_kernel(self.bathymetry.depth, n0, e0, 1.0 / dn, 1.0 / de, particles, turn, offsets,
                         depths, tide, out)
        return out

    def _per_sounding(self, nb: int, variance, map_variance, counts) -> tuple[np.ndarray, ...]:
        """A ping's per-sounding arrays (variances, map error variances, counts) with their
        defaults, of shape ``(nb,)``."""
        v = np.full(nb, self.sigma**2) if variance is None else np.asarray(variance, dtype=np.float64)
        mv = np.zeros(nb) if map_variance is None else np.asarray(map_variance, dtype=np.float64)
        c = np.ones(nb) if counts is None else np.asarray(counts, dtype=np.float64)
        for name, value in (("variance", v), ("map_variance", mv), ("counts", c)):
            if value.shape != (nb,):
                raise TangraphError(f"{name} must have shape ({nb},), got {value.shape}")
        return v, mv, c

    def ping_update(self, particles, offsets, depths, tide, tide_var: float, *, turn=None, weights=None,
                    variance=None, map_variance=None, exponent=None, scale=None,
                    counts=None) -> PingLikelihood:
        """The likelihood of a ping for every particle (module docstring).

        Parameters
        ----------
        particles : (N, 2)
        offsets, depths : (B, 2), (B,)
            The ping's soundings (NaN depths are skipped with their offsets).
        tide, tide_var : (N,), float
            The particles' Gaussian tide posteriors ``N(tide_p, tide_var)`` (0: known tide).
        turn : (N,), optional
            Each particle's angle turning its offsets about it (rad).
        weights : (N,), optional
            The cloud's weights (normalised here; default equal): they weigh the sub-cloud means
            and the exponents.
        variance, map_variance : (B,), optional
            Each sounding's variance ``v_b`` (default ``sigma^2``) and its map error variance
            (default 0: a perfect map, exponents 1).
        exponent : (B,), optional
            The exponents of an earlier evaluation of the same ping (default: from this cloud).
        scale : tangraph.sensors.MisfitScale, optional
            The local misfit scale to integrate out (a Student-t likelihood,
            :mod:`tangraph.sensors.misfit`); None: the variances as stated (Gaussian).
        counts : (B,), optional
            Each sounding's expected whitened square (:func:`tangraph.sensors.misfit_counts`;
            default 1), summed into the effective counts the scale is updated with.

        Raises
        ------
        TangraphError
            Arrays of the wrong shapes, ``tide_var`` negative or not finite, variances not
            positive.
        """
        particles, offsets, depths, turn = self._checked(particles, offsets, depths, turn, keep_nan=True)
        n, nb = particles.shape[0], depths.size
        tide = np.ascontiguousarray(tide, dtype=np.float64)
        if tide.shape != (n,):
            raise TangraphError(f"tide must have shape ({n},) as particles, got {tide.shape}")
        try:
            t_var = float(tide_var)
        except (TypeError, ValueError):
            t_var = np.nan
        if not (np.isfinite(t_var) and t_var >= 0):
            raise TangraphError(f"tide_var must be a finite number >= 0, got {tide_var!r}")
        v, mv, c = self._per_sounding(nb, variance, map_variance, counts)
        keep = np.isfinite(depths)
        if not keep.all():
            offsets, depths, v, mv, c = offsets[keep], depths[keep], v[keep], mv[keep], c[keep]
            exponent = None if exponent is None else np.asarray(exponent)[keep]
            nb = depths.size
        if not np.all(v > 0):
            raise TangraphError("the soundings' variances must be positive")
        if nb == 0:  # nothing measured: no information
            return PingLikelihood(np.zeros(n), tide.copy(), t_var, np.full(n, np.nan), np.ones(0),
                                  np.zeros(n))
        w = np.full(n, 1.0 / n) if weights is None else np.asarray(weights, dtype=np.float64)
        if w.shape != (n,):
            raise TangraphError(f"weights must have shape ({n},) as particles, got {w.shape}")
        w = w / w.sum()
        residual = self.residuals(particles, np.ascontiguousarray(offsets), np.ascontiguousarray(depths),
                                  tide, turn=turn)
        given = exponent is not None
        alpha = np.array(exponent, dtype=np.float64) if given else np.empty(nb)
        if alpha.shape != (nb,):
            raise TangraphError(f"exponent must have shape ({nb},), got {alpha.shape}")
        log_likelihood, shift, total = np.empty(n), np.empty(n), np.empty(n)
        residual_sum, count = np.zeros(n), np.zeros(n)
        quadratic, effective = np.empty(n), np.zeros(n)
        shape, rate = (0.0, 1.0) if scale is None else (float(scale.shape), float(scale.rate))
        _update_kernel(residual, w, 1.0 / v, mv, alpha, given, t_var, shape, rate, np.ascontiguousarray(c),
                       log_likelihood, shift, total, residual_sum, count, quadratic, effective)
        with np.errstate(invalid="ignore", divide="ignore"):
            predicted = np.where(count > 0, np.mean(depths) - residual_sum / count, np.nan)
        new_var = t_var / (1.0 + t_var * float(w @ total)) if t_var > 0 else 0.0
        return PingLikelihood(log_likelihood, tide + shift, new_var, predicted, alpha, count / nb,
                              None if scale is None else quadratic, None if scale is None else effective)

    def tide_update(
        self, particles, offsets, depths, tide, tide_var: float, *, turn=None
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`ping_update` with the default variances, equal weights and a perfect map:
        ``(log_likelihood, tide, predicted)``; see the module docstring for the algebra.

        Raises
        ------
        TangraphError
            ``particles`` not ``(N, 2)``, ``offsets`` and ``depths`` not ``(B, 2)`` and ``(B,)``,
            ``tide`` or ``turn`` not ``(N,)``, ``tide_var`` negative or not finite.
        """
        update = self.ping_update(particles, offsets, depths, tide, tide_var, turn=turn)
        return update.log_likelihood, update.tide, update.predicted


def log_normalise(logw: np.ndarray, *, where: str = "") -> tuple[np.ndarray, float]:
    """Normalised weights and the log of their sum, computed stably.

    Raises
    ------
    FilterDivergence
        Every weight is zero (all ``-inf``), naming ``where``.
    """
    top = np.max(logw)
    if not np.isfinite(top):
        raise FilterDivergence(f"{where}: all {logw.size} particles have zero likelihood (filter diverged)")
    w = np.exp(logw - top)
    total = w.sum()
    return w / total, float(top + np.log(total))


def effective_sample_size(weights: np.ndarray) -> float:
    """``1 / sum(w^2)`` of normalised weights."""
    return float(1.0 / np.sum(np.square(weights)))
