"""A fix's confidence regions, covariances and quality (:func:`tangraph.matching.tap_fix`): the
sub-cell quadric, the region thresholds (Xie, Wang, calibrated), the covariances from the
likelihood's moments, its curvature, the Cramér-Rao bound and the ping jackknife, and the flags
that say whether the graph may trust the fix."""

from __future__ import annotations

import numpy as np
from scipy import ndimage, stats

from tangraph.matching.search import CandidateGrid, criterion_sums
from tangraph.matching.tap_types import FixQuality, Region, RegionMethod, TapConfig

__all__ = ["region_thresholds"]


def _quadric(
    surface: np.ndarray, i: int | np.integer, j: int | np.integer, step: float
) -> tuple[np.ndarray, np.ndarray | None]:
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


def _drift_threshold(drift, inflation: float, q_min: float, n: int, alpha: float) -> float | None:
    """The calibrated region's threshold on ``Q`` with the tide's drift within the window (its
    sandwich ``drift``: the covariance it adds to the fix and the fix's without it), the
    inflation at least their mean generalised eigenvalue: whether the prediction is allowed is
    asked of it (:func:`_quality`). None without a drift."""
    if drift is None:
        return None
    widened = max(inflation, 1.0 + float(np.trace(np.linalg.solve(drift[1], drift[0]))) / 2.0)
    return region_thresholds(q_min, n, alpha, widened)[RegionMethod.CALIBRATED]


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
    their generalised eigenvectors (``a`` where ``b`` is smaller everywhere), taken in the
    whitening of whichever is positive definite (a region's covariance is singular when the
    window's likelihood is flat along an axis of the search: then ``b`` where it is larger); the
    sum when neither is; ``a`` if either is not finite (an infinite one says the window is
    uninformative)."""
    if not (np.all(np.isfinite(a)) and np.all(np.isfinite(b))):
        return a
    for base, other in ((a, b), (b, a)):
        try:
            low = np.linalg.cholesky(base)
        except np.linalg.LinAlgError:
            continue
        inv = np.linalg.inv(low)
        w, v = np.linalg.eigh(inv @ other @ inv.T)
        out = low @ (v * np.maximum(w, 1.0)) @ v.T @ low.T
        return 0.5 * (out + out.T)
    return a + b


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


def _quality(
    q, q_min, region: Region, config: TapConfig, best: tuple[int | np.integer, int | np.integer],
    centre_threshold: float | None = None,
) -> FixQuality:
    """The fix's quality flags from its calibrated ``region``; whether the search's centre (the
    prediction) is allowed is asked of ``centre_threshold`` on ``q`` when given (a likelihood
    wider than the window's own shape: the tide's drift), else of the region."""
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
    middle = (mask.shape[0] // 2, mask.shape[1] // 2)  # the search is centred on the prediction
    centre = bool(mask[middle] if centre_threshold is None else q[middle] <= centre_threshold)
    return FixQuality(peak_ratio, int(n_basins), area_fraction, touches, tuple(reasons), on_edge, centre)
