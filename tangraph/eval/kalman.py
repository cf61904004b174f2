"""The covariance recursions of a linear-Gaussian chain: the Kalman filter's and the
Rauch-Tung-Striebel smoother's (the posterior Cramér-Rao bound without a map error,
:mod:`tangraph.eval.crb`, is these on the survey's linearised error state).

The chain is ``x_{k+1} = F_k x_k + N(0, Q_k)``, ``x_0 ~ N(0, P_0)``, and ping ``k`` brings the
information ``L_k L_k^T`` on ``x_k``; only covariances are propagated (no data).
"""

from __future__ import annotations

import numpy as np

from tangraph.errors import TangraphError

__all__ = ["covariance_filter", "covariance_smoother"]


def covariance_filter(p0: np.ndarray, f: np.ndarray, q: np.ndarray,
                      factor: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Kalman filter covariances: filtered (K, n, n) and predicted ``P_{k+1|k}`` (K-1, n, n).

    The update of ping k is ``P - P L (I + L^T P L)^-1 L^T P``, the information form
    ``(P^-1 + L L^T)^-1`` written so that a singular ``P`` (the walk's zero start) is fine.
    """
    k, n = factor.shape[0], p0.shape[0]
    filtered = np.empty((k, n, n))
    predicted = np.empty((max(k - 1, 0), n, n))
    eye = np.eye(factor.shape[2])
    informed = np.any(factor != 0.0, axis=(1, 2))
    p = p0
    for i in range(k):
        if i:
            p = f[i - 1] @ p @ f[i - 1].T + q[i - 1]
            predicted[i - 1] = p
        if informed[i]:
            pl = p @ factor[i]
            p = p - pl @ np.linalg.solve(eye + factor[i].T @ pl, pl.T)
            p = 0.5 * (p + p.T)
        filtered[i] = p
    return filtered, predicted


def covariance_smoother(filtered: np.ndarray, predicted: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Rauch-Tung-Striebel smoother covariances from the filter's."""
    smoothed = np.empty_like(filtered)
    smoothed[-1] = filtered[-1]
    if filtered.shape[0] == 1:
        return smoothed
    try:  # G_k^T = P_{k+1|k}^-1 F_k P_k
        gain_t = np.linalg.solve(predicted, f @ filtered[:-1])
    except np.linalg.LinAlgError:
        raise TangraphError("posterior_crb: a predicted covariance is singular; the smoother bound "
                            "is not defined (is a noise std zero with no prior?)") from None
    for i in range(filtered.shape[0] - 2, -1, -1):
        g = gain_t[i].T
        s = filtered[i] + g @ (smoothed[i + 1] - predicted[i]) @ g.T
        smoothed[i] = 0.5 * (s + s.T)
    return smoothed
