"""Terrain-aided position fixes (TAP): batch match, confidence regions, covariance, quality.

The fix follows Wang et al. (2019, eqs. 3-6): for each candidate position X of the patch the
tide ``t(X)`` is the mean residual and ``sigma^2(X)`` the residual variance; the fix minimises
``sigma^2``. With ``Q(X) = (n - 1) sigma^2(X)`` and ``S(X) = sum (d - t_p)^2`` (tide of the fix):

- **Xie** (eq. 2): ``Q(X) <= Q(X_p) chi2_{1-a}(n-1) / (n-1)``;
- **Wang** (eq. 18): ``S(X) <= S(X_p) [1 + chi2_{1-a}(n-1) / (n-1)]``;
- **calibrated** (ours): the profile-likelihood-ratio region ``Q(X) - Q(X_p) <= c s^2
  chi2_{1-a}(2)`` with ``s^2 = Q(X_p) / (n - 3)`` (two position parameters and the tide
  estimated) and ``c >= 1`` the variance inflation of spatially correlated residuals: a
  cluster-robust (per ping) sandwich ratio of the score's variance for errors shared by a ping's
  beams (attitude), times the lag-one AR(1) factor ``(1 + r) / (1 - r)`` along each beam's track.

The map's error. Where the patch carries the map error its soundings share with the survey's
other soundings (:func:`tangraph.sensors.shared_map_variances`, the terrain measurement model's
row-sum bound), the fix's covariance is at least the least-squares fix's covariance with the
soundings' variances ``s^2 + shared_b`` (a sandwich on the map gradients at the fix): the
residual scatter cannot show an error the window's soundings share with each other or with the
survey's other passes over the same cells, and a graph that adds every window's fix must not
count that error once per window. The regions and the quality flags are those of the window's
own likelihood (its shape: one basin or several, compact or flat): the variance inflation ``c``
is at least the sandwich ratio with the map error its soundings share among themselves, computed
exactly on the gradients (``Patch.error``, :func:`tangraph.sensors.shared_quadratic`: soundings
whose gradients differ share map error that cancels in the fix, which a row-sum bound would
count as if it added up), and which the sharing of its map error with other windows and passes
does not change.

The tide's drift (``NavigationModel.tide_drift``): the window's tide is its mean, and the drift's
change along the window, which every sounding of a ping shares, moves the least-squares fix; the
fix's covariance is at least the least-squares one with the drift's covariance between the
window's pings (a sandwich on the map gradients, ``covariances["map"]``). The regions keep the
window's own likelihood: widened by the drift's mean generalised eigenvalue, as by the window's
own map error, they refused most windows of a simulated survey whose tide drifts and of Lake
Caputh's, and the online graph's fixes fell from 245 to 53 in four runs (12.3 against 7.5 m).
Whether the prediction is allowed (``FixQuality.holds_centre``, which the online graph's checks
ask) is asked of the region so widened, the window's likelihood with the drift: the window's own
region left a right prediction out of about half the drifting windows of a test, whenever the
drift had moved the fix.

A candidate is valid when every sounding of the window has a map depth there; a prior off the
map is searched around like any other (the window may reach the map's data from there).

Covariances: from the curvature of ``Q`` at the fix (``2 c s^2 H^-1``, the inverse Fisher
information of eq. 14), from the second moments of the normalised likelihood over the search
grid (``exp(-(Q - Q_p) / (2 c s^2))``; honest for flat or multimodal surfaces; where the
likelihood is narrower than the grid step, the Cramér-Rao bound's), and the Cramér-Rao bound of the
window from the map gradients.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.geometry import mahalanobis2
from tangraph.geometry import rotate as _rotate
from tangraph.maps.grid import BathymetryMap
from tangraph.matching.patch import MatchingError, Patch, window_patch
from tangraph.matching.search import CandidateGrid, CriterionSums, criterion_sums
from tangraph.matching.tap_noise import (
    _drift_sandwich,
    _gradient,
    _map_sandwich,
    _variance_inflation,
    _window_sandwich,
)
from tangraph.matching.tap_regions import (
    _covariances,
    _drift_threshold,
    _jackknife,
    _larger,
    _quadric,
    _quality,
    _regions,
    _residual_variance,
    region_thresholds,
)
from tangraph.matching.tap_types import Criterion, FixQuality, Region, RegionMethod, TapConfig, TapFix
from tangraph.survey import Survey

__all__ = [
    "Criterion",
    "FixQuality",
    "Region",
    "RegionMethod",
    "TapConfig",
    "TapFix",
    "criterion_at",
    "nees",
    "region_thresholds",
    "rotate",
    "tap_fix",
    "tap_fix_patch",
]


def rotate(offsets: np.ndarray, angle: float) -> np.ndarray:
    """Offsets ``(N, 2)`` (north, east) rotated clockwise (as headings grow) by ``angle``."""
    return _rotate(angle, offsets)


def criterion_at(
    bathymetry: BathymetryMap, patch: Patch, positions, heading: float = 0.0, tide: float | None = None
) -> np.ndarray:
    """``Q`` (tide profiled) or, given ``tide`` (measured = map + tide, as ``TapFix.tide``), ``S``
    at a few positions ``(M, 2)``: the slow, exact evaluation used to test the truth against the
    regions."""
    positions = np.atleast_2d(np.asarray(positions, float))
    offsets = rotate(patch.offsets, heading)
    h = bathymetry.depth_at(positions[:, 0:1] + offsets[:, 0], positions[:, 1:2] + offsets[:, 1])
    d = h - patch.depths
    t = d.mean(axis=1, keepdims=True) if tide is None else -tide
    return np.sum((d - t) ** 2, axis=1)


def nees(error, covariance) -> float:
    """Normalised estimation error squared ``e^T P^-1 e``."""
    return float(mahalanobis2(error, covariance))


def tap_fix(
    survey: Survey,
    bathymetry: BathymetryMap,
    end: int,
    n_pings: int,
    config: TapConfig | None = None,
    *,
    prior=None,
    shared=None,
    error=None,
    drift: tuple[float, float] | None = None,
) -> TapFix:
    """A fix of the window of ``n_pings`` pings ending at ``end``, searched around ``prior``
    (default: the dead-reckoned position of ping ``end``); ``shared (K, B)``: the survey's
    shared map error variances (:func:`tangraph.sensors.shared_map_variances`; None: a perfect
    map), which widen the fix, and ``error`` the map's error
    (:func:`tangraph.sensors.map_error`), whose part shared among the window's own soundings
    widens its regions; ``drift``: the tide's drift ``(std, time)``
    (``NavigationModel.tide_drift``), whose change within the window widens the fix's
    covariance.

    Raises
    ------
    MatchingError
        An empty or too sparse window, a prior off the map, or no candidate with every
        sounding on the map.
    """
    config = config or TapConfig()
    patch = window_patch(survey, end, n_pings, min_soundings=config.min_soundings, shared=shared, error=error,
                         drift=drift)
    return tap_fix_patch(patch, bathymetry, config, prior=prior)


def _search(patch: Patch, bathymetry: BathymetryMap, config: TapConfig, prior: np.ndarray,
            step: float) -> tuple[CandidateGrid, CriterionSums]:
    """The candidate grid around ``prior`` and the criterion's sums on it; a MatchingError when no
    candidate has every sounding on the map."""
    grid = CandidateGrid.around(prior, config.half_width, step, np.asarray(config.headings))
    method = (
        "direct"
        if config.criterion is Criterion.MAD and config.search_method == "auto"
        else config.search_method
    )
    sums = criterion_sums(bathymetry, patch.offsets, patch.depths, grid, method=method)
    if not np.any(sums.valid):
        raise MatchingError(
            f"window {patch.first}..{patch.reference}: no candidate within {config.half_width} m of "
            f"{prior.tolist()} has every sounding on the map"
        )
    return grid, sums


def tap_fix_patch(patch: Patch, bathymetry: BathymetryMap, config: TapConfig, *, prior=None) -> TapFix:
    """:func:`tap_fix` of a prepared :class:`Patch`."""
    prior = patch.reference_position if prior is None else np.asarray(prior, float)
    if prior.shape != (2,) or not np.all(np.isfinite(prior)):  # an estimator that lost its way
        raise MatchingError(f"window {patch.first}..{patch.reference}: the search centre must be a "
                            f"finite (north, east), got {prior.tolist()!r}")
    step = config.step or min(bathymetry.cell_size)
    grid, sums = _search(patch, bathymetry, config, prior, step)
    n = patch.n_soundings
    sigma2 = sums.sigma2()
    score = {
        Criterion.MLE: sigma2,
        Criterion.MSD: sums.msd(),
        Criterion.MAD: sums.mad(),
        Criterion.CORRELATION: -sums.correlation(),
    }[config.criterion]
    if not np.any(np.isfinite(score)):
        raise MatchingError(
            f"criterion {config.criterion.value} is not available from search {sums.method!r}"
        )
    k_h, i, j = np.unravel_index(np.nanargmin(score), score.shape)
    heading = float(grid.headings[k_h])
    if heading:  # the patch turned once by the best heading; everything below reads it as it is
        patch = dataclasses.replace(patch, offsets=rotate(patch.offsets, heading))
    q = (n - 1) * sigma2[k_h]
    q_min = float(np.nanmin(q))  # regions and covariances live on Q, whatever picked the fix
    tide = float(sums.tide()[k_h, i, j])
    node = np.array([grid.north[i], grid.east[j]])
    shift, _ = _quadric(score[k_h], i, j, step)
    position = node + shift
    if config.criterion is Criterion.MLE and np.any(shift):  # keep the refinement only if it helps
        q_node, q_refined = criterion_at(bathymetry, patch, np.vstack([node, position]))
        if not q_refined < q_node:
            position = node

    inflation = _variance_inflation(bathymetry, patch, position, tide) if config.calibrate else 1.0
    s2 = _residual_variance(q_min, n)
    has_error = patch.shared is not None or patch.error is not None or patch.drift is not None
    gradient = _gradient(bathymetry, patch, position) if has_error else None
    within = _window_sandwich(gradient, s2, patch, position)
    if within is not None:  # the map error the window's own soundings share shapes its likelihood
        inflation = max(inflation, within)
    shared = _map_sandwich(gradient, s2, patch.shared)
    covariances = _covariances(
        q, q_min, s2 * inflation, grid, i, j, step, bathymetry, patch, position
    )
    regions = _regions(q, sums.rss_fixed_tide(tide)[k_h], q_min, n, inflation, config.alpha, step)
    covariance = covariances[config.covariance]
    if shared is not None:
        covariances["map"] = shared[1]
    drift = _drift_sandwich(gradient, s2, patch)
    if drift is not None:  # the least-squares fix's covariance with the tide's drift besides
        covariances["map"] = (drift[1] if shared is None else shared[1]) + drift[0]
    if "map" in covariances:
        covariance = _larger(covariance, covariances["map"])
    if config.jackknife:
        jack = _jackknife(bathymetry, patch, grid, i, j, step)
        if jack is not None:
            covariances["jackknife"] = jack
            covariance = _larger(covariance, jack)
    quality = _quality(q, q_min, regions[RegionMethod.CALIBRATED], config, (i, j),
                       _drift_threshold(drift, inflation, q_min, n, config.alpha))
    return TapFix(
        index=patch.reference,
        first=patch.first,
        position=position,
        covariance=covariance,
        tide=-tide,  # the search's sums hold map - measured
        sigma=float(np.sqrt(sigma2[k_h, i, j])),
        n_soundings=n,
        method=config.criterion,
        heading_offset=heading,
        covariances=covariances,
        regions=regions,
        quality=quality,
        grid=grid,
        surface=q,
        variance_inflation=float(inflation),
        prior=prior,
    )
