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
is at least the same sandwich ratio with the map error its soundings share among themselves
(``Patch.within``, :func:`tangraph.sensors.shared_among`), which the sharing of its map error
with other windows and passes does not change.

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
import enum
from typing import Literal

import numpy as np
from scipy import ndimage, stats

from tangraph.errors import TangraphError
from tangraph.geometry import mahalanobis2
from tangraph.geometry import rotate as _rotate
from tangraph.maps.grid import BathymetryMap
from tangraph.matching.patch import MatchingError, Patch, window_patch
from tangraph.matching.search import CandidateGrid, CriterionSums, criterion_sums
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


class Criterion(enum.StrEnum):
    """What the fix minimises (or, for correlation, maximises)."""

    MLE = "mle"  # sigma^2 with the tide removed (Wang et al. eqs. 3-6)
    MSD = "msd"
    MAD = "mad"
    CORRELATION = "correlation"


class RegionMethod(enum.StrEnum):
    XIE = "xie"
    WANG = "wang"
    CALIBRATED = "calibrated"


@dataclasses.dataclass(frozen=True)
class TapConfig:
    """Settings of a fix. ``step`` defaults to the map's cell size; angles in radians."""

    half_width: float = 50.0
    step: float | None = None
    headings: tuple[float, ...] = (0.0,)
    criterion: Criterion = Criterion.MLE
    alpha: float = 0.05
    covariance: Literal["region", "curvature", "crlb"] = "region"
    calibrate: bool = True
    jackknife: bool = True
    min_soundings: int = 10
    search_method: Literal["auto", "direct", "fft"] = "auto"
    max_area_fraction: float = 0.5

    def __post_init__(self) -> None:
        if not 0.0 < self.alpha < 1.0:
            raise TangraphError(f"TapConfig: alpha must lie in (0, 1), got {self.alpha!r}")
        if not (np.isfinite(self.half_width) and self.half_width > 0):
            raise TangraphError(f"TapConfig: half_width must be positive, got {self.half_width!r}")
        if self.step is not None and not (np.isfinite(self.step) and self.step > 0):
            raise TangraphError(f"TapConfig: step must be positive, got {self.step!r}")
        if self.covariance not in ("region", "curvature", "crlb"):
            raise TangraphError(
                f"TapConfig: covariance must be region, curvature or crlb, got {self.covariance!r}"
            )
        if self.search_method not in ("auto", "direct", "fft"):
            raise TangraphError(
                f"TapConfig: search_method must be auto, direct or fft, got {self.search_method!r}"
            )
        object.__setattr__(self, "criterion", Criterion(self.criterion))
        object.__setattr__(self, "headings", tuple(float(h) for h in self.headings))


@dataclasses.dataclass(frozen=True, eq=False)
class Region:
    """A confidence region as a mask over the candidate grid (at the fix's heading)."""

    method: RegionMethod
    alpha: float
    mask: np.ndarray  # (nn, ne) bool
    threshold: float  # on Q (Xie, calibrated) or on S (Wang)
    area: float  # m^2


@dataclasses.dataclass(frozen=True)
class FixQuality:
    """Figures that say whether the graph may trust a fix."""

    peak_ratio: float  # criterion of the best separate basin / criterion at the fix (inf if none)
    n_basins: int  # connected parts of the calibrated region
    area_fraction: float  # calibrated region area / search area
    touches_edge: bool  # the calibrated region reaches the edge of the search grid
    reasons: tuple[str, ...]  # why the fix is flagged; empty if it is not
    best_on_edge: bool = False  # the best candidate lies on the outer ring of the search grid

    @property
    def outside(self) -> bool:
        """The best match lies on the edge of the search: the best fit is likely outside it
        (the prediction the search was centred on is wrong by more than its half-width)."""
        return self.best_on_edge

    @property
    def informative(self) -> bool:
        return not any(r.startswith("uninformative") for r in self.reasons)

    @property
    def multimodal(self) -> bool:
        return any(r.startswith("multimodal") for r in self.reasons)


@dataclasses.dataclass(frozen=True, eq=False)
class TapFix:
    """A terrain-aided position fix of the window of pings from ``first`` to ``index``."""

    index: int
    first: int
    position: np.ndarray  # (2,) north, east
    covariance: np.ndarray  # (2, 2), the one chosen by TapConfig.covariance
    tide: float  # mean of measured - map at the fix: the tide, measured = map + tide
    sigma: float  # std of the sounding error, sqrt of Wang's eq. 4 at the fix
    n_soundings: int
    method: Criterion
    heading_offset: float
    covariances: dict[str, np.ndarray]
    regions: dict[RegionMethod, Region]
    quality: FixQuality
    grid: CandidateGrid
    surface: np.ndarray  # Q over the grid at the fix's heading, NaN where invalid
    variance_inflation: float
    prior: np.ndarray

    @property
    def accepted(self) -> bool:
        """Informative and unimodal: fit to become a prior factor."""
        return self.quality.informative and not self.quality.multimodal

    @property
    def region(self) -> Region:
        return self.regions[RegionMethod.CALIBRATED]


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
) -> TapFix:
    """A fix of the window of ``n_pings`` pings ending at ``end``, searched around ``prior``
    (default: the dead-reckoned position of ping ``end``); ``shared (K, B)``: the survey's
    shared map error variances (:func:`tangraph.sensors.shared_map_variances`; None: a perfect
    map), which widen the fix, and ``error`` the map's error
    (:func:`tangraph.sensors.map_error`), whose part shared among the window's own soundings
    widens its regions.

    Raises
    ------
    MatchingError
        An empty or too sparse window, a prior off the map, or no candidate with every
        sounding on the map.
    """
    config = config or TapConfig()
    patch = window_patch(survey, end, n_pings, min_soundings=config.min_soundings, shared=shared, error=error)
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
    gradient = _gradient(bathymetry, patch, position) if patch.shared is not None else None
    within = _map_sandwich(gradient, s2, patch.within)
    if within is not None:  # the map error the window's own soundings share shapes its likelihood
        inflation = max(inflation, within[0])
    shared = _map_sandwich(gradient, s2, patch.shared)
    regions = _regions(q, sums.rss_fixed_tide(tide)[k_h], q_min, n, inflation, config.alpha, step)
    covariances = _covariances(
        q, q_min, s2 * inflation, grid, i, j, step, bathymetry, patch, position
    )
    covariance = covariances[config.covariance]
    if shared is not None:
        covariances["map"] = shared[1]
        covariance = _larger(covariance, shared[1])
    if config.jackknife:
        jack = _jackknife(bathymetry, patch, grid, i, j, step)
        if jack is not None:
            covariances["jackknife"] = jack
            covariance = _larger(covariance, jack)
    quality = _quality(q, q_min, regions[RegionMethod.CALIBRATED], config, (i, j))
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


def _quadric(surface: np.ndarray, i: int, j: int, step: float) -> tuple[np.ndarray, np.ndarray | None]:
    """Sub-cell minimum and Hessian (per m^2) of a quadric fitted to the 3 x 3 cells around (i, j)."""
    nn, ne = surface.shape
    if not (0 < i < nn - 1 and 0 < j < ne - 1):
        return np.zeros(2), None
    z = surface[i - 1 : i + 2, j - 1 : j + 2]
    if not np.all(np.isfinite(z)):
        return np.zeros(2), None
    y, x = np.mgrid[-1:2, -1:2].astype(float)
    design = np.column_stack(
        [np.ones(9), y.ravel(), x.ravel(), y.ravel() ** 2, y.ravel() * x.ravel(), x.ravel() ** 2]
    )
    c = np.linalg.lstsq(design, z.ravel(), rcond=None)[0]
    hessian = np.array([[2 * c[3], c[4]], [c[4], 2 * c[5]]])
    if np.any(np.linalg.eigvalsh(hessian) <= 0):
        return np.zeros(2), None
    shift = np.clip(-np.linalg.solve(hessian, c[1:3]), -0.5, 0.5)
    return shift * step, hessian / step**2


def _residuals(bathymetry, patch, position, tide):
    offsets = patch.offsets
    return bathymetry.depth_at(position[0] + offsets[:, 0], position[1] + offsets[:, 1]) - patch.depths - tide


def _lag_one(r: np.ndarray, major: np.ndarray, minor: np.ndarray) -> float:
    """Lag-one correlation of residuals ordered by (major, minor), pairs with minor + 1; 0 unless
    it is significant (above two standard errors, 2 / sqrt(pairs)), so white noise is not
    inflated by the estimate's own scatter."""
    order = np.lexsort((minor, major))
    r, major, minor = r[order], major[order], minor[order]
    pair = (major[1:] == major[:-1]) & (minor[1:] == minor[:-1] + 1)
    if pair.sum() < 3:
        return 0.0
    rho = float(np.sum(r[1:][pair] * r[:-1][pair]) / np.sum(r**2))
    return rho if rho > 2.0 / np.sqrt(pair.sum()) else 0.0


def _ping_sandwich(r: np.ndarray, gradient: np.ndarray, ping: np.ndarray) -> float | None:
    """Cluster-robust (per ping) over i.i.d. variance of the position score, averaged over the two
    directions; None with fewer than 5 pings (too few clusters to estimate it)."""
    pings, cluster = np.unique(ping, return_inverse=True)
    if pings.size < 5:
        return None
    g = gradient - gradient.mean(axis=0)
    iid = (g.T @ g) * np.sum(r**2) / max(r.size - 3, 1)
    score = np.zeros((pings.size, 2))
    np.add.at(score, cluster, g * r[:, None])
    robust = score.T @ score * pings.size / (pings.size - 1)
    try:
        ratio = float(np.trace(np.linalg.solve(iid, robust)) / 2)
    except np.linalg.LinAlgError:
        return None
    # the ratio of white noise scatters by about sqrt(2 / (pings - 1)): count only a clear excess
    return ratio if ratio > 1.0 + 2.0 * np.sqrt(2.0 / (pings.size - 1)) else 1.0


def _variance_inflation(bathymetry, patch, position, tide) -> float:
    """How much spatially correlated residuals widen the likelihood: within a ping a
    cluster-robust (sandwich) ratio of the score's variance (any error shared by a ping's beams,
    such as an attitude error), or the lag-one AR(1) factor along the beams when the window has too
    few pings; across pings the lag-one AR(1) factor along each beam's track."""
    r = _residuals(bathymetry, patch, position, tide)
    if not np.all(np.isfinite(r)) or not np.any(r):
        return 1.0
    offsets = patch.offsets
    gradient = bathymetry.gradient_at(position[0] + offsets[:, 0], position[1] + offsets[:, 1])
    within = _ping_sandwich(r, gradient, patch.ping) if np.all(np.isfinite(gradient)) else None
    if within is None:
        rho = float(np.clip(_lag_one(r, patch.ping, patch.beam), 0.0, 0.95))
        within = (1 + rho) / (1 - rho)
    rho = float(np.clip(_lag_one(r, patch.beam, patch.ping), 0.0, 0.95))
    return max(1.0, within) * (1 + rho) / (1 - rho)


def _gradient(bathymetry, patch, position) -> np.ndarray:
    """The map gradient ``(N, 2)`` at the patch's soundings placed at ``position``."""
    return bathymetry.gradient_at(position[0] + patch.offsets[:, 0], position[1] + patch.offsets[:, 1])


def _map_sandwich(g, s2, shared) -> tuple[float, np.ndarray] | None:
    """Given the map gradients ``g (N, 2)`` at the soundings and their shared map error variances
    ``shared (N,)``: the covariance of the least-squares fix with the soundings' variances
    ``s^2 + shared_b`` (a sandwich on the gradients, the tide's mean removed) and its ratio to
    the one with ``s^2`` alone (the mean of their generalised eigenvalues); None without a map
    error or a gradient."""
    if g is None or shared is None or not np.any(shared > 0):
        return None
    ok = np.all(np.isfinite(g), axis=1) & np.isfinite(shared)
    if ok.sum() < 3:
        return None
    g = g[ok] - g[ok].mean(axis=0)
    information = g.T @ g
    if np.linalg.cond(information) > 1e12:
        return None
    inverse = np.linalg.inv(information)
    sandwich = inverse @ ((g * (s2 + shared[ok])[:, None]).T @ g) @ inverse
    ratio = float(np.trace(information @ sandwich) / (2.0 * s2))
    return max(ratio, 1.0), 0.5 * (sandwich + sandwich.T)


# The smallest residual variance a window is credited with (m^2): soundings that fit the map
# exactly (noise-free, or the map made from them) leave no scatter to scale regions by.
_MIN_RESIDUAL_VARIANCE = 1e-12


def _residual_variance(q_min: float, n: int) -> float:
    """The soundings' residual variance at the best fit, ``Q_min / (n - 3)`` (at least
    ``_MIN_RESIDUAL_VARIANCE``)."""
    return max(q_min / max(n - 3, 1), _MIN_RESIDUAL_VARIANCE)


def region_thresholds(
    q_min: float, n: int, alpha: float, inflation: float = 1.0
) -> dict[RegionMethod, float]:
    """Thresholds of the three regions at level ``1 - alpha``: on ``Q`` for Xie and calibrated,
    on ``S`` (tide fixed at the fix's) for Wang; see the module docstring."""
    ratio = stats.chi2.ppf(1 - alpha, n - 1) / (n - 1)
    s2 = _residual_variance(q_min, n)
    return {
        RegionMethod.XIE: q_min * ratio,
        RegionMethod.WANG: q_min * (1 + ratio),
        RegionMethod.CALIBRATED: q_min + inflation * s2 * stats.chi2.ppf(1 - alpha, 2),
    }


def _regions(q, s_fixed, q_min, n, inflation, alpha, step) -> dict[RegionMethod, Region]:
    valid = np.isfinite(q)
    out = {}
    for method, threshold in region_thresholds(q_min, n, alpha, inflation).items():
        surface = s_fixed if method is RegionMethod.WANG else q
        mask = valid & (np.where(valid, surface, np.inf) <= threshold)
        out[method] = Region(method, alpha, mask, float(threshold), float(mask.sum() * step * step))
    return out


def _covariances(
    q, q_min, s2, grid, i, j, step, bathymetry, patch, position
) -> dict[str, np.ndarray]:
    valid = np.isfinite(q)
    weight = np.where(valid, np.exp(-(np.where(valid, q, q_min) - q_min) / (2 * s2)), 0.0)
    weight /= weight.sum()
    nn, ee = np.meshgrid(grid.north, grid.east, indexing="ij")
    mean = np.array([np.sum(weight * nn), np.sum(weight * ee)])
    dn, de = nn - mean[0], ee - mean[1]
    moments = np.array(
        [
            [np.sum(weight * dn * dn), np.sum(weight * dn * de)],
            [np.sum(weight * dn * de), np.sum(weight * de * de)],
        ]
    )
    _, hessian = _quadric(q, i, j, step)
    curvature = 2 * s2 * np.linalg.inv(hessian) if hessian is not None else None
    # A likelihood narrower than the grid step is not resolved by its moments on the grid: there
    # the Fisher information at the fix says more; without it, the grid's quantisation bounds it.
    crlb = _crlb(bathymetry, patch, position, s2)
    if np.linalg.eigvalsh(moments).max() >= step**2:
        region = moments
    elif np.all(np.isfinite(crlb)):  # locally linear: the Fisher information at the fix
        region = crlb
    else:
        region = moments + np.eye(2) * step**2 / 12
    curvature = region if curvature is None else curvature
    return {"region": region, "curvature": curvature, "crlb": crlb}


def _jackknife(bathymetry, patch, grid, i, j, step, reach: int = 20) -> np.ndarray | None:
    """Ping-jackknife covariance of the fix: the fix of the window without each of its ``P``
    pings in turn (the minimum of ``Q`` without that ping's soundings, the tide profiled over the
    rest, refined by a quadric), ``(P - 1) / P`` times the scatter of those ``P`` positions about
    their mean. Pings are the clusters of the window's errors (attitude, sound velocity, a bad
    ping), so this is the cluster-robust variance of the fix; it is large when the fix rests on
    one ping (a ping in error can move a whole window's fix on gentle terrain). Always on ``Q``
    (the MLE criterion), where the regions and the other covariances live too. Searched within
    ``reach`` steps of the fix, on the patch as turned by the best heading: a leave-one-out
    minimum beyond that is taken on the edge, which understates a spread that is then large
    anyway. None with fewer than five pings."""
    pings, cluster = np.unique(patch.ping, return_inverse=True)
    if pings.size < 5:
        return None
    nn, ne = grid.shape[1:]
    rows = slice(max(i - reach, 0), min(i + reach + 1, nn))
    cols = slice(max(j - reach, 0), min(j + reach + 1, ne))
    sub = CandidateGrid(grid.north[rows], grid.east[cols])
    shape = (pings.size, sub.north.size, sub.east.size)
    s1, s2, count = np.zeros(shape), np.zeros(shape), np.bincount(cluster).astype(float)
    for n in range(pings.size):
        mine = cluster == n
        sums = criterion_sums(bathymetry, patch.offsets[mine], patch.depths[mine], sub, method="direct")
        s1[n], s2[n] = sums.sum_d[0], sums.sum_d2[0]
    total1, total2, total = s1.sum(axis=0), s2.sum(axis=0), count.sum()
    positions = np.empty((pings.size, 2))
    for n in range(pings.size):
        q = (total2 - s2[n]) - (total1 - s1[n]) ** 2 / (total - count[n])
        if not np.any(np.isfinite(q)):
            return None
        a, b = np.unravel_index(np.nanargmin(q), q.shape)
        shift, _ = _quadric(q, a, b, step)
        positions[n] = (sub.north[a] + shift[0], sub.east[b] + shift[1])
    d = positions - positions.mean(axis=0)
    return (pings.size - 1) / pings.size * (d.T @ d)


def _larger(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest covariance at least as large as ``a`` and as ``b`` in every direction of
    ``a``'s generalised eigenvectors (``a`` where ``b`` is smaller everywhere; ``a`` if it is not
    positive definite or either is not finite: an infinite one says the window is
    uninformative)."""
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return a
    try:
        low = np.linalg.cholesky(a)
    except np.linalg.LinAlgError:
        return a
    inv = np.linalg.inv(low)
    w, v = np.linalg.eigh(inv @ b @ inv.T)
    out = low @ (v * np.maximum(w, 1.0)) @ v.T @ low.T
    return 0.5 * (out + out.T)


def _crlb(bathymetry, patch, position, s2) -> np.ndarray:
    """Inverse Fisher information of the window's soundings at ``position`` (the tide absorbs the
    mean gradient); infinite where it is singular."""
    offsets = patch.offsets
    g = bathymetry.gradient_at(position[0] + offsets[:, 0], position[1] + offsets[:, 1])
    g = g[np.all(np.isfinite(g), axis=1)]
    g = g - g.mean(axis=0)
    information = g.T @ g / s2
    if g.shape[0] < 3 or np.linalg.cond(information) > 1e12:
        return np.full((2, 2), np.inf)
    return np.linalg.inv(information)


def _quality(q, q_min, region: Region, config: TapConfig, best: tuple[int, int]) -> FixQuality:
    labels, n_basins = ndimage.label(region.mask)
    mask = region.mask
    touches = bool(mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any())
    area_fraction = float(mask.mean())
    filled = np.where(np.isfinite(q), q, np.inf)
    minima = (filled == ndimage.minimum_filter(filled, size=3)) & np.isfinite(filled)
    main = ndimage.binary_dilation(
        labels == labels[np.unravel_index(np.argmin(filled), q.shape)], iterations=2
    )
    others = minima & ~main
    peak_ratio = float(filled[others].min() / q_min) if others.any() and q_min > 0 else np.inf
    i, j = best  # the node the criterion chose
    on_edge = bool(i in (0, q.shape[0] - 1) or j in (0, q.shape[1] - 1))
    reasons = []
    if on_edge:
        reasons.append("outside: the best match lies on the edge of the search grid")
    if n_basins > 1:
        reasons.append(f"multimodal: the calibrated region has {n_basins} separate parts")
    if touches:
        reasons.append("uninformative: the calibrated region reaches the edge of the search grid")
    if area_fraction > config.max_area_fraction:
        reasons.append(f"uninformative: the calibrated region covers {area_fraction:.0%} of the search area")
    return FixQuality(peak_ratio, int(n_basins), area_fraction, touches, tuple(reasons), on_edge)
