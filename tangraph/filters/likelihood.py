"""The one terrain likelihood every particle filter shares, in compiled kernels.

The model is :mod:`tangraph.sensors.terrain`'s: sounding ``b`` of a ping measures
``z_b = h(x + o_b) + tide + e_b`` with ``h`` the map's bilinear depth (the rules of
:mod:`tangraph.maps._interp`) and ``e_b`` of variance ``v_b`` (the sounding's noise plus the map
error it shares with the survey's other soundings: the row-sum bound). Where a map states its
error per cell, the error is read **where the cloud puts the sounding**: ``v_b = noise^2 +
sum_f n_fb E_w[g_f(x_p + R(turn_p) o_b)]``, the cloud's weighted mean of each error field's
variance ``g_f`` at the particles' footprints times the number of the survey's soundings that
share it (:func:`tangraph.sensors.sounding_map_counts`); judged once per ping, as the exponents
below are. (At the dead-reckoned footprints, tens of metres off the truth, a sounding in a
filled gap between the map's lines was trusted as one on a line; the filters then followed the
gaps' error and held it with confidence.) For particle ``p`` with
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
  sounding ``b`` spread beyond the map's error there (1 with a perfect map; the map's error
  read where the cloud puts the sounding when the ping carries ``map_counts``, else at its
  dead-reckoned footprint); computed once per ping from the weighted cloud and passed back in
  for the same ping's later evaluations (tempering stages, IPF children) so that their
  likelihood ratios are of one function. Weighed whole instead (``a_b = 1``), the point-mass
  filter was more accurate on the simulated realistic maps but over-confident on Lake Caputh,
  whose map errs beyond its statement in patches (``experiments/caputh_replay``, the section
  on the map's error read where the belief puts the soundings).

- **a misfit scale of its own** (:mod:`tangraph.sensors.misfit`): given a ``Gamma(shape, rate)``
  on the precision factor shared by the ping's soundings, the quadratic ``Q`` above (the tide
  integrated out at the scale's estimate ``rate / shape``) enters the Student-t
  ``lgamma(shape + n/2) - lgamma(shape) + shape log(rate) - (shape + n/2) log(rate + Q/2)``
  with ``n`` the particle's summed expected squares ``a_b c_b``; a sounding without a map depth
  under a particle adds to its ``Q`` the sub-cloud's weighted mean of ``a_b r^2 / v_b`` and to its
  ``n`` its ``a_b c_b`` (so every particle's Student-t has the same count, and none gains by having
  no map under a sounding).

Constants shared by all particles are dropped: weights are normalised. The kernels are in
:mod:`tangraph.filters.likelihood_kernels`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.likelihood_kernels import (
    _field_variance_kernel,
    _residual_kernel,
    _residual_sums_kernel,
    _update_kernel,
)
from tangraph.maps.grid import BathymetryMap

__all__ = [
    "FilterDivergence",
    "OffMap",
    "PingLikelihood",
    "TerrainLikelihood",
    "effective_sample_size",
    "log_normalise",
]


# The cloud's particles (drawn systematically by weight) over which the map's error under each
# sounding is averaged: a smooth field's mean, to a few per cent, at a small share of a ping's cost.
JUDGED = 128


class FilterDivergence(TangraphError):
    """Every particle has zero likelihood: the filter has lost the vehicle."""


class OffMap(FilterDivergence):
    """No sounding of a ping has the map under any particle: the ping says nothing about where
    the vehicle is (it is not evidence against any particle)."""


@dataclasses.dataclass(frozen=True, eq=False)
class PingLikelihood:
    """The terrain likelihood of one ping for every particle (from
    :meth:`TerrainLikelihood.ping_update`): ``log_likelihood (N,)`` (up to a constant; ``-inf``
    everywhere when no sounding has the map under any particle), the posterior tide means
    ``tide (N,)`` and their shared variance ``tide_var``, the mean predicted depth ``predicted
    (N,)`` (the ping's mean measured depth less the particle's mean residual; NaN for a particle
    with the map under none of its soundings), the exponents ``exponent (B,)`` and the share of
    soundings with the map under each particle, ``mapped (N,)``; the soundings' variances
    ``variance (B,)`` and expected whitened squares ``counts (B,)`` the ping was weighed with
    (what a later evaluation of the same ping reuses)."""

    log_likelihood: np.ndarray
    tide: np.ndarray
    tide_var: float
    predicted: np.ndarray
    exponent: np.ndarray
    mapped: np.ndarray
    quadratic: np.ndarray | None = None
    count: np.ndarray | None = None
    variance: np.ndarray | None = None
    counts: np.ndarray | None = None


@dataclasses.dataclass(frozen=True, eq=False)
class TerrainLikelihood:
    """The terrain likelihood on a map, with a default sounding std ``sigma`` (m) and known
    ``tide`` for the calls that give no per-sounding variances (see the module docstring)."""

    bathymetry: BathymetryMap
    sigma: float
    tide: float = 0.0
    error_grids: np.ndarray | None = None

    def __post_init__(self) -> None:
        if not (np.isfinite(self.sigma) and self.sigma > 0):
            raise TangraphError(f"TerrainLikelihood: sigma must be positive, got {self.sigma!r}")
        if self.error_grids is not None:
            grids = np.ascontiguousarray(self.error_grids, dtype=np.float64)
            if grids.ndim != 3 or grids.shape[:2] != self.bathymetry.shape or not np.all(grids >= 0):
                raise TangraphError(f"TerrainLikelihood: error_grids must be (ny, nx, F) variances >= 0 on "
                                    f"the map's {self.bathymetry.shape} grid, got {grids.shape}")
            object.__setattr__(self, "error_grids", grids)

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

    def _judged(self, particles, offsets, turn, weights, map_counts) -> tuple[np.ndarray, np.ndarray]:
        """Each sounding's map error variance read where the cloud puts it: the bound's share
        ``sum_f map_counts[b, f] E_w[g_f]`` and its own ``sum_f E_w[g_f]`` ``(B,)``, the cloud's
        weighted means taken over ``JUDGED`` particles drawn from it systematically (all of a
        smaller cloud; :func:`_field_variance_kernel`)."""
        nb = offsets.shape[0]
        counts = np.asarray(map_counts, dtype=np.float64)
        fields = 0 if self.error_grids is None else self.error_grids.shape[2]
        if self.error_grids is None or counts.shape != (nb, fields):
            raise TangraphError(f"map_counts must have shape ({nb}, {fields}) (the map's error fields), "
                                f"got {counts.shape}")
        if particles.shape[0] > JUDGED:  # a systematic draw: deterministic, of equal weights
            drawn = np.searchsorted(np.cumsum(weights), (np.arange(JUDGED) + 0.5) / JUDGED * weights.sum())
            drawn = np.minimum(drawn, particles.shape[0] - 1)
            particles, turn, weights = particles[drawn], turn[drawn], np.ones(JUDGED)
        field = np.empty((nb, fields))
        n0, e0, dn, de = self.bathymetry._grid  # type: ignore[attr-defined]
        _field_variance_kernel(self.bathymetry.depth, self.error_grids, n0, e0, 1.0 / dn, 1.0 / de,
                               np.ascontiguousarray(particles), np.ascontiguousarray(turn), offsets,
                               np.ascontiguousarray(weights), field)
        return np.sum(counts * field, axis=1), np.sum(field, axis=1)

    def _placed(self, particles, offsets, turn, weights, map_counts, noise, counts,
                misfit: bool) -> tuple[np.ndarray, ...]:  # fmt: skip
        """A ping's variances (the soundings' ``noise`` plus the map error the cloud places,
        :meth:`_judged`), the map's own error variance under each sounding where the cloud puts
        it (for the exponents) and, with a ``misfit`` scale, the expected whitened squares of
        those variances (else ``counts`` as given)."""
        shared, own = self._judged(particles, offsets, turn, weights, map_counts)
        if misfit:
            counts = np.minimum((noise + own) / (noise + shared), 1.0)
        return noise + shared, own, counts

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
                    variance=None, map_variance=None, exponent=None, scale=None, counts=None,
                    map_counts=None) -> PingLikelihood:
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
            With ``map_counts``, ``variance`` is each sounding's own noise variance.
        scale : tangraph.sensors.MisfitScale, optional
            The local misfit scale to integrate out (a Student-t likelihood,
            :mod:`tangraph.sensors.misfit`); None: the variances as stated (Gaussian).
        counts : (B,), optional
            Each sounding's expected whitened square (:func:`tangraph.sensors.misfit_counts`;
            default 1), summed into the effective counts the scale is updated with.
        map_counts : (B, F), optional
            With the map's error grids (``error_grids``): each sounding's map error is read where
            the cloud puts it, its variance ``variance_b + sum_f map_counts[b, f] E_w[g_f]``
            (``g_f`` the variance of the error's field ``f`` at a particle's footprint, ``E_w``
            the cloud's weighted mean; :func:`tangraph.sensors.sounding_map_counts`), and the
            exponents are judged against the map's own error there, ``sum_f E_w[g_f]``. The
            variances judged are returned (``variance``) for later evaluations of the same ping.

        Raises
        ------
        TangraphError
            Arrays of the wrong shapes, ``tide_var`` negative or not finite, variances not
            positive.
        """
        particles, offsets, depths, turn = self._checked(particles, offsets, depths, turn, keep_nan=True)
        n, nb = particles.shape[0], depths.size
        tide, t_var = _tide(tide, tide_var, n)
        v, mv, c = self._per_sounding(nb, variance, map_variance, counts)
        keep = np.isfinite(depths)
        if not keep.all():
            offsets, depths, v, mv, c = offsets[keep], depths[keep], v[keep], mv[keep], c[keep]
            exponent = None if exponent is None else np.asarray(exponent)[keep]
            map_counts = None if map_counts is None else np.asarray(map_counts)[keep]
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
        residual = self.residuals(particles, offsets, depths, tide, turn=turn)
        if map_counts is not None:
            v, mv, c = self._placed(particles, offsets, turn, w, map_counts, v, c, counts is not None)
        given = exponent is not None
        alpha = np.array(exponent, dtype=np.float64) if given else np.empty(nb)
        if alpha.shape != (nb,):
            raise TangraphError(f"exponent must have shape ({nb},), got {alpha.shape}")
        log_likelihood, shift, total, quadratic = np.empty(n), np.empty(n), np.empty(n), np.empty(n)
        residual_sum, count, effective = np.zeros(n), np.zeros(n), np.zeros(n)
        shape, rate = (0.0, 1.0) if scale is None else (float(scale.shape), float(scale.rate))
        _update_kernel(residual, w, 1.0 / v, mv, alpha, given, t_var, shape, rate, np.ascontiguousarray(c),
                       log_likelihood, shift, total, residual_sum, count, quadratic, effective)
        with np.errstate(invalid="ignore", divide="ignore"):
            predicted = np.where(count > 0, np.mean(depths) - residual_sum / count, np.nan)
        new_var = t_var / (1.0 + t_var * float(w @ total)) if t_var > 0 else 0.0
        held = scale is not None
        return PingLikelihood(log_likelihood, tide + shift, new_var, predicted, alpha, count / nb,
                              quadratic if held else None, effective if held else None, v, c)

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


def _tide(tide, tide_var, n: int) -> tuple[np.ndarray, float]:
    """The particles' tide means ``(n,)`` and their variance, checked."""
    tide = np.ascontiguousarray(tide, dtype=np.float64)
    if tide.shape != (n,):
        raise TangraphError(f"tide must have shape ({n},) as particles, got {tide.shape}")
    try:
        t_var = float(tide_var)
    except (TypeError, ValueError):
        t_var = np.nan
    if not (np.isfinite(t_var) and t_var >= 0):
        raise TangraphError(f"tide_var must be a finite number >= 0, got {tide_var!r}")
    return tide, t_var


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
