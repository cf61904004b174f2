"""The point-mass filter's calibration bank: Gauss-Hermite nodes in the DR's constant errors.

The joint density of ``(position, k, b)`` is held at the nodes of a product Gauss-Hermite rule of
a Gaussian in the calibration (:func:`_place_nodes`). The calibration's posterior is that
Gaussian times the evidence since, fitted as a quadratic at the nodes (:func:`_evidence_fit`);
the nodes are re-placed when it has moved from their placement (:func:`_calibration_moved`).
See :mod:`tangraph.filters.pmf`.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import numpy as np

from tangraph.geometry import mahalanobis2, rotation_matrix

if TYPE_CHECKING:
    from tangraph.filters.pmf_grid import PointMass

__all__ = ["CellSpread"]


# the calibration's nodes are re-placed when its posterior std leaves [r, 1 / r] times the
# placement's, or its mean moves by this many placement stds
_NODE_RATIO = 0.7
_NODE_SHIFT = 0.5


# the most a fitted evidence is sharpened for the cells' smoothing (the largest eigenvalue of
# ``cell @ curvature`` taken; 1 would be an evidence as sharp as the cells allow)
_MAX_SHARPEN = 0.9


def _evidence_fit(nodes: np.ndarray, evidence: np.ndarray, mean: np.ndarray, cov: np.ndarray,
                  cell: np.ndarray | None = None):
    """The Gaussian ``N(mean, cov)`` times the exponential of the least-squares quadratic through
    the log ``evidence (M,)`` at ``nodes (M, 2)``, its curvature made positive semi-definite (a
    likelihood's): the posterior is never wider than the prior, exact when the evidence is
    Gaussian in the calibration however narrow it is against the nodes' spacing. The mean is
    kept inside the nodes' bounding box (the fit does not extrapolate). Axes of prior variance
    0, or on which the nodes do not vary, keep the prior; without enough finite evidence for a
    quadratic, the prior is returned. With the ``cell (2, 2)`` each node stands for
    (:func:`_place_nodes`), a member's evidence is the calibration's likelihood averaged over
    its cell: a Gaussian likelihood of curvature ``H`` gives evidence of curvature ``(H^-1 +
    cell)^-1`` with the same peak, so the fit is sharpened back to ``H`` (by at most
    ``1 / (1 - _MAX_SHARPEN)``). Returns the mean, the covariance and whether the fitted
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
    if cell is not None and np.any(cell[np.ix_(live, live)]):  # the cells' smoothing taken back
        smooth = cell[np.ix_(live, live)] / np.outer(std[live], std[live])
        rho = float(np.max(np.abs(np.linalg.eigvals(smooth @ h))))
        if rho > _MAX_SHARPEN:
            h = h * (_MAX_SHARPEN / rho)
        eye = np.eye(live.size)
        g = np.linalg.solve(eye - h @ smooth, g)
        h = h @ np.linalg.inv(eye - smooth @ h)
        h = 0.5 * (h + h.T)
    correlation = cov[np.ix_(live, live)] / np.outer(std[live], std[live])
    posterior = np.linalg.inv(np.linalg.inv(correlation) + h)
    out_mean, out_cov = mean.copy(), cov.copy()
    box = nodes[:, live]
    out_mean[live] = np.clip(mean[live] + std[live] * (posterior @ g), box.min(axis=0), box.max(axis=0))
    out_cov[np.ix_(live, live)] = posterior * np.outer(std[live], std[live])
    return out_mean, out_cov, bool(np.all(values > 0))


def _cell_share(count: int) -> float:
    """The share of an axis's variance that each of ``count`` Gauss-Hermite nodes stands for:
    the variance ``d^2 / 12`` of a uniform cell as wide as the standard rule's central spacing
    ``d`` (0.25 for 3 nodes, 0.15 for 5); 1 for a single node, which stands for the whole axis.

    >>> _cell_share(1), _cell_share(3)
    (1.0, 0.25)
    """
    if count == 1:
        return 1.0
    x, _ = np.polynomial.hermite_e.hermegauss(count)
    return float(min(np.min(np.diff(np.sort(x))) ** 2 / 12.0, 1.0))


def _place_nodes(mean: np.ndarray, cov: np.ndarray, counts: tuple[int, int]
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Calibration nodes ``(M, 2)`` of the product Gauss-Hermite rule of ``counts`` points along
    the principal axes of ``N(mean, cov)``, their log weights ``(M,)`` (summing to 1) and the
    calibration covariance ``(2, 2)`` each node stands for (its cell): on each axis the rule is
    laid on ``1 - s`` of the axis's variance and each node stands for the other ``s``
    (:func:`_cell_share`), so the members together keep the Gaussian's mean and covariance."""
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    order = np.argsort(np.argmax(np.abs(vectors), axis=0))  # principal axis nearest k first, then b
    values, vectors = np.maximum(values[order], 0.0), vectors[:, order]
    share = np.array([_cell_share(c) if v > 0 else 0.0 for c, v in zip(counts, values, strict=True)])
    rules = []
    for c, v in zip(counts, values, strict=True):
        if c == 1 or v <= 0:
            rules.append((np.zeros(1), np.ones(1)))
        else:
            x, w = np.polynomial.hermite_e.hermegauss(c)
            rules.append((x, w / w.sum()))
    (x0, w0), (x1, w1) = rules
    xi = np.stack(np.meshgrid(x0, x1, indexing="ij"), axis=-1).reshape(-1, 2)
    nodes = mean + xi * np.sqrt((1.0 - share) * values) @ vectors.T
    cell = (vectors * (share * values)) @ vectors.T
    return nodes, np.log(np.outer(w0, w1).ravel()), 0.5 * (cell + cell.T)


_J = np.array([[0.0, -1.0], [1.0, 0.0]])  # d R(a) / da = R(a) _J


@dataclasses.dataclass(frozen=True)
class CellSpread:
    """What the calibration a member stands for, but its node does not hold, does to its
    positions. A member moves by its node's calibrated increments ``R(-b) u / (1 + k)``; the
    calibrations of its cell (``cell (2, 2)``, :func:`_place_nodes`) would have moved it by
    ``M d`` more, ``M`` the Jacobian of ``R(-b) X / (1 + k)`` in ``(k, b)`` and ``X`` the DR
    displacement since the nodes were placed (``travel``), and the heading walk since (its
    variances ``v_i`` grown at displacements ``X_i``: ``walk = (sum v_i, sum v_i X_i, sum v_i X_i
    X_i^T)``) by ``A (X - X_i) delta_i``. Their covariance grows as ``X`` does; what of it
    is new at a step (its positive semi-definite part) is convolved into every member as
    the white DR noise is, ``applied`` what has been. Without it, members whose nodes hold
    heading errors degrees apart part by tens of metres along a line, with no point between
    them, and the terrain picks one with confidence (the caputh_replay study)."""

    cell: np.ndarray
    travel: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(2))
    walk: tuple[float, np.ndarray, np.ndarray] = (0.0, np.zeros(2), np.zeros((2, 2)))
    applied: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((2, 2)))

    def step(self, increment, walk: float, calibration) -> tuple[CellSpread, np.ndarray]:
        """After a DR ``increment (2,)`` (the DR's world frame) with the heading walk's
        variance ``walk`` grown over it, at the calibration ``(k, b)`` the nodes were placed
        about: the new spread and the covariance ``(2, 2)`` to convolve in now."""
        v, s1, s2 = self.walk
        x0 = self.travel
        if walk > 0:
            v, s1, s2 = v + walk, s1 + walk * x0, s2 + walk * np.outer(x0, x0)
        x = x0 + np.asarray(increment, float)
        k, b = float(calibration[0]), float(calibration[1])
        turn = rotation_matrix(-b) / (1.0 + k)
        jac = np.column_stack([-(turn @ x) / (1.0 + k), -(turn @ _J @ x)])
        rotated = -turn @ _J
        walked = v * np.outer(x, x) - np.outer(x, s1) - np.outer(s1, x) + s2
        target = jac @ self.cell @ jac.T + rotated @ walked @ rotated.T
        values, vectors = np.linalg.eigh(0.5 * (target - self.applied + (target - self.applied).T))
        new = (vectors * np.maximum(values, 0.0)) @ vectors.T
        return CellSpread(self.cell, x, (v, s1, s2), self.applied + new), new


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
