"""Graduated non-convexity: which measurements of a graph are inliers.

The batch smoother does not trust every fix: a block of bad pings (a shifted swath, a depth
bias) can give fixes that agree with nothing else, and a wrong start prior can be the odd one
out. :func:`gnc` finds the inliers by graduated non-convexity with a truncated least-squares
(TLS) loss (Yang, Antonante, Tzoumas & Carlone 2020, "Graduated Non-Convexity for Robust Spatial
Perception"), with the rules of GTSAM's ``GncOptimizer`` (TLS, linear scheduler): start from the
least-squares solution with every weight 1 and ``mu`` from the largest residual (remark 5 of the
paper), then alternate the weights of eq. 14 and a weighted solve from the initial values,
raising ``mu`` by ``mu_step``, until the weights are binary or the cost stops moving.

GTSAM's own ``GncLMOptimizer`` re-weights a factor by cloning it with a new noise model, and
``CustomFactor`` (the calibrated fix factor of :mod:`tangraph.graph.calibration`) has no
``clone`` in GTSAM 4.3 ("Attempting to clone factor with no clone() implemented"); so the loop
runs here, each candidate re-made by a factory with its information times its weight, and is
tested against ``gtsam.GncLMOptimizer`` on a graph of native factors
(``tests/graph/test_robust.py``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import gtsam
import numpy as np
from scipy import stats

__all__ = ["GncResult", "gnc"]

Factory = Callable[[int, float], gtsam.NonlinearFactor]
Solve = Callable[[gtsam.NonlinearFactorGraph, gtsam.Values], gtsam.Values]


@dataclasses.dataclass(frozen=True, eq=False)
class GncResult:
    """The outcome of :func:`gnc`: the estimate, each candidate's final ``weights`` (1 inlier, 0
    outlier), the ``iterations`` of the outer loop and the last ``mu``."""

    values: gtsam.Values
    weights: np.ndarray
    iterations: int
    mu: float

    @property
    def inliers(self) -> np.ndarray:
        return self.weights >= 0.5


def _tls_weights(errors: np.ndarray, thresholds: np.ndarray, mu: float) -> np.ndarray:
    """Eq. 14 of the GNC paper (GTSAM's TLS weights, linear scheduler) of the candidates' factor
    errors ``0.5 |r|^2`` against their thresholds ``barc^2``."""
    upper = (mu + 1.0) / mu * thresholds
    lower = mu / (mu + 1.0) * thresholds
    with np.errstate(divide="ignore", invalid="ignore"):
        between = np.sqrt(thresholds * mu * (mu + 1.0) / errors) - mu
    weights = np.clip(np.nan_to_num(between, nan=1.0, posinf=1.0), 0.0, 1.0)
    weights[errors >= upper] = 0.0
    weights[errors <= lower] = 1.0
    return weights


def gnc(
    fixed: Sequence[gtsam.NonlinearFactor],
    candidate: Factory,
    n_candidates: int,
    initial: gtsam.Values,
    solve: Solve,
    *,
    probability: float = 0.99,
    mu_step: float = 1.4,
    max_iterations: int = 100,
    relative_cost_tol: float = 1e-5,
    weights_tol: float = 1e-4,
) -> GncResult:
    """Graduated non-convexity (TLS) over the ``n_candidates`` factors of ``candidate``.

    Parameters
    ----------
    fixed : sequence of gtsam factors
        Known inliers (odometry, priors that are never wrong).
    candidate : callable ``(i, weight) -> factor``
        Candidate ``i`` with its information multiplied by ``weight`` (> 0).
    n_candidates : int
    initial : gtsam.Values
        The initial estimate; every weighted solve starts from it (as GTSAM's).
    solve : callable ``(graph, values) -> values``
        A nonlinear least-squares solve of a graph from ``values``.
    probability, mu_step, max_iterations, relative_cost_tol, weights_tol
        GTSAM's ``GncParams`` of the same names (``setInlierCostThresholdsAtProbability``,
        ``muStep``, ``maxIterations``, ``relativeCostTol``, ``weightsTol``).

    Returns
    -------
    GncResult
    """
    unit = [candidate(i, 1.0) for i in range(n_candidates)]
    # a factor is an inlier while its error 0.5 |r|^2 is below 0.5 chi2(probability, its dimension)
    thresholds = 0.5 * stats.chi2.ppf(probability, np.array([f.dim() for f in unit], int))

    def weighted(weights: np.ndarray) -> gtsam.NonlinearFactorGraph:
        graph = gtsam.NonlinearFactorGraph()
        for factor in fixed:
            graph.add(factor)
        for i, w in enumerate(weights):
            if w > 0:
                graph.add(unit[i] if w == 1.0 else candidate(i, float(w)))
        return graph

    def errors(values: gtsam.Values) -> np.ndarray:
        return np.array([f.error(values) for f in unit])

    weights = np.ones(n_candidates)
    graph = weighted(weights)
    result = solve(graph, initial)
    if n_candidates == 0:
        return GncResult(result, weights, 0, -1.0)
    # mu from the largest residual at the initial values, of every factor (GTSAM: remark 5)
    every = [*fixed, *unit]
    start = np.array([f.error(initial) for f in every])
    limits = np.concatenate([0.5 * stats.chi2.ppf(probability, [f.dim() for f in fixed]), thresholds])
    excess = 2.0 * start - limits
    mu = float(np.min(limits[excess > 0] / excess[excess > 0])) if np.any(excess > 0) else np.inf
    if not np.isfinite(mu) or mu <= 0:  # every residual below its threshold: least squares
        return GncResult(result, weights, 0, -1.0)
    mu = max(mu, 1e-6)
    previous = graph.error(result)
    iteration = 0
    while iteration < max_iterations:
        iteration += 1
        weights = _tls_weights(errors(result), thresholds, mu)
        graph = weighted(weights)
        result = solve(graph, initial)
        cost = graph.error(result)
        binary = np.all(np.abs(weights - np.round(weights)) <= weights_tol)
        if abs(cost - previous) / max(previous, 1e-7) < relative_cost_tol or binary:
            break
        mu *= mu_step
        previous = cost
    return GncResult(result, weights, iteration, mu)
