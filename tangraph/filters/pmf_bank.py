"""The point-mass filter's calibration bank: Gauss-Hermite nodes in the DR's constant errors.

The joint density of ``(position, k, b)`` is held at the nodes of a product Gauss-Hermite rule of
a Gaussian in the calibration (:func:`_place_nodes`). The calibration's posterior is that
Gaussian times the evidence since, fitted as a quadratic at the nodes (:func:`_evidence_fit`);
the nodes are re-placed when it has moved from their placement (:func:`_calibration_moved`).
See :mod:`tangraph.filters.pmf`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from tangraph.geometry import mahalanobis2

if TYPE_CHECKING:
    from tangraph.filters.pmf_grid import PointMass

__all__: list[str] = []


# the calibration's nodes are re-placed when its posterior std leaves [r, 1 / r] times the
# placement's, or its mean moves by this many placement stds
_NODE_RATIO = 0.7
_NODE_SHIFT = 0.5


def _evidence_fit(nodes: np.ndarray, evidence: np.ndarray, mean: np.ndarray, cov: np.ndarray):
    """The Gaussian ``N(mean, cov)`` times the exponential of the least-squares quadratic through
    the log ``evidence (M,)`` at ``nodes (M, 2)``, its curvature made positive semi-definite (a
    likelihood's): the posterior is never wider than the prior, exact when the evidence is
    Gaussian in the calibration however narrow it is against the nodes' spacing. The mean is
    kept inside the nodes' bounding box (the fit does not extrapolate). Axes of prior variance
    0, or on which the nodes do not vary, keep the prior; without enough finite evidence for a
    quadratic, the prior is returned. Returns the mean, the covariance and whether the fitted
    evidence was concave (a Gaussian likelihood)."""
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    live = np.flatnonzero((std > 0) & (np.ptp(nodes, axis=0) > 0))
    pairs = [(i, j) for i in range(live.size) for j in range(i, live.size)]
    keep = np.isfinite(evidence)
    if live.size == 0 or keep.sum() < 1 + live.size + len(pairs):
        return mean.copy(), cov.copy(), False
    x = (nodes[keep][:, live] - mean[live]) / std[live]
    columns = [np.ones(len(x)), *x.T, *(x[:, i] * x[:, j] for i, j in pairs)]
    coef = np.linalg.lstsq(np.column_stack(columns), evidence[keep], rcond=None)[0]
    g = coef[1:1 + live.size]
    h = np.zeros((live.size, live.size))
    for c, (i, j) in zip(coef[1 + live.size:], pairs, strict=True):
        h[i, j] = h[j, i] = -c if i != j else -2.0 * c
    values, vectors = np.linalg.eigh(h)
    h = (vectors * np.maximum(values, 0.0)) @ vectors.T  # a likelihood's curvature
    correlation = cov[np.ix_(live, live)] / np.outer(std[live], std[live])
    posterior = np.linalg.inv(np.linalg.inv(correlation) + h)
    out_mean, out_cov = mean.copy(), cov.copy()
    box = nodes[:, live]
    out_mean[live] = np.clip(mean[live] + std[live] * (posterior @ g), box.min(axis=0), box.max(axis=0))
    out_cov[np.ix_(live, live)] = posterior * np.outer(std[live], std[live])
    return out_mean, out_cov, bool(np.all(values > 0))


def _place_nodes(mean: np.ndarray, cov: np.ndarray, counts: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Calibration nodes ``(M, 2)`` of the product Gauss-Hermite rule of ``counts`` points along
    the principal axes of ``N(mean, cov)`` (one node on an axis of variance 0) and their log
    weights ``(M,)`` (summing to 1)."""
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    order = np.argsort(np.argmax(np.abs(vectors), axis=0))  # principal axis nearest k first, then b
    values, vectors = values[order], vectors[:, order]
    rules = []
    for c, v in zip(counts, values, strict=True):
        if c == 1 or v <= 0:
            rules.append((np.zeros(1), np.ones(1)))
        else:
            x, w = np.polynomial.hermite_e.hermegauss(c)
            rules.append((x, w / w.sum()))
    (x0, w0), (x1, w1) = rules
    xi = np.stack(np.meshgrid(x0, x1, indexing="ij"), axis=-1).reshape(-1, 2)
    nodes = mean + xi * np.sqrt(np.maximum(values, 0.0)) @ vectors.T
    return nodes, np.log(np.outer(w0, w1).ravel())


def _log_gaussian(nodes: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """``log N(nodes; mean, cov)`` up to a constant (axes of variance 0 left out)."""
    live = np.diag(cov) > 0
    if not live.any():
        return np.zeros(len(nodes))
    d = (nodes - mean)[:, live]
    return -0.5 * mahalanobis2(d, cov[np.ix_(live, live)])


def _calibration_moved(state: PointMass) -> bool:
    """Whether the calibration's posterior has left the nodes' placement: its std out of
    ``[_NODE_RATIO, 1 / _NODE_RATIO]`` times the placement's on an axis, or its mean moved by
    more than ``_NODE_SHIFT`` placement stds."""
    mean, cov = state.calibration()
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    placed_mean, placed_std = state.placed
    live = (placed_std > 0) & (np.ptp(state.nodes, axis=0) > 0)
    if not live.any():
        return False
    grown = np.sqrt(placed_std[live] ** 2 + np.array([0.0, state.walk])[live])
    ratio = std[live] / grown
    return bool(np.any(ratio < _NODE_RATIO) or np.any(ratio > 1.0 / _NODE_RATIO)
                or np.any(np.abs(mean - placed_mean)[live] > _NODE_SHIFT * placed_std[live]))
