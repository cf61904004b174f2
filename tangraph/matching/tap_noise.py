"""How much a window's residuals widen its fix (:func:`tangraph.matching.tap_fix`): the variance
inflation of spatially correlated residuals (a cluster-robust sandwich per ping, lag-one AR(1)
factors along beams and tracks) and the sandwich of the map error the soundings share."""

from __future__ import annotations

import numpy as np


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


def _centred(g: np.ndarray | None, ok=True) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """The finite gradients ``g`` (where also ``ok``) with their mean removed (the tide estimated
    with the fix), their information ``g^T g`` and the rows kept; None without gradients, with
    fewer than 3 or when the information is singular."""
    if g is None:
        return None
    ok = np.all(np.isfinite(g), axis=1) & ok
    if ok.sum() < 3:
        return None
    g = g[ok] - g[ok].mean(axis=0)
    information = g.T @ g
    return None if np.linalg.cond(information) > 1e12 else (g, information, ok)


def _window_sandwich(g, s2, patch, position) -> float | None:
    """How much the map error the window's own soundings share among themselves widens its
    likelihood: the mean generalised eigenvalue of the least-squares fix's covariance with that
    error (the exact quadratic form :func:`tangraph.sensors.shared_quadratic` of the map
    gradients at the soundings placed at ``position``, the tide's mean removed) over the one
    without, at least 1; None without a map error or a gradient."""
    centred = None if patch.error is None else _centred(g)
    if centred is None:
        return None
    g, information, ok = centred
    from tangraph.sensors.terrain import shared_quadratic

    offsets = patch.offsets[ok]
    shared = shared_quadratic(position[0] + offsets[:, 0], position[1] + offsets[:, 1], g, patch.error)
    return max(1.0 + float(np.trace(np.linalg.solve(information, shared))) / (2.0 * s2), 1.0)


def _map_sandwich(g, s2, shared) -> tuple[float, np.ndarray] | None:
    """Given the map gradients ``g (N, 2)`` at the soundings and their shared map error variances
    ``shared (N,)``: the covariance of the least-squares fix with the soundings' variances
    ``s^2 + shared_b`` (a sandwich on the gradients, the tide's mean removed) and its ratio to
    the one with ``s^2`` alone (the mean of their generalised eigenvalues); None without a map
    error or a gradient."""
    centred = None if shared is None or not np.any(shared > 0) else _centred(g, np.isfinite(shared))
    if centred is None:
        return None
    g, information, ok = centred
    inverse = np.linalg.inv(information)
    sandwich = inverse @ ((g * (s2 + shared[ok])[:, None]).T @ g) @ inverse
    ratio = float(np.trace(information @ sandwich) / (2.0 * s2))
    return max(ratio, 1.0), 0.5 * (sandwich + sandwich.T)


def _drift_sandwich(g, s2, patch) -> tuple[np.ndarray, np.ndarray] | None:
    """How the tide's drift within the window widens its fix: every sounding of a ping shares
    the drift (``patch.drift``, between the window's pings), whose window mean the tide takes
    and whose change along the window the least-squares fix reads as position. Returns the
    covariance it adds to the least-squares fix, ``I^-1 H^T C H I^-1`` (``H`` the per-ping sums
    of the gradients with their mean removed, ``I`` their information), and the fix's
    covariance without it, ``s^2 I^-1``; None without a drift or a gradient."""
    centred = None if patch.drift is None else _centred(g)
    if centred is None:
        return None
    g, information, ok = centred
    per_ping = np.zeros((patch.drift.shape[0], 2))
    np.add.at(per_ping, patch.ping[ok] - patch.first, g)
    inverse = np.linalg.inv(information)
    added = inverse @ (per_ping.T @ patch.drift @ per_ping) @ inverse
    return 0.5 * (added + added.T), s2 * inverse
