"""The covariance recursions (tangraph.eval.kalman) against the inverse of the chain's dense
information."""

import numpy as np

from tangraph.eval.kalman import covariance_filter, covariance_smoother


def _chain(k=7, n=3, seed=2):
    rng = np.random.default_rng(seed)
    f = np.eye(n) + 0.3 * rng.standard_normal((k - 1, n, n))
    root = rng.standard_normal((k - 1, n, n))
    q = root @ np.swapaxes(root, 1, 2) + 0.1 * np.eye(n)
    factor = rng.standard_normal((k, n, 2))
    factor[2] = 0.0  # a ping that says nothing
    return np.diag([4.0, 1.0, 0.5]), f, q, factor


def _dense(p0, f, q, factor, last):
    """The joint covariance of x_0..x_last from the dense information of the chain."""
    n = p0.shape[0]
    size = n * (last + 1)
    info = np.zeros((size, size))
    info[:n, :n] += np.linalg.inv(p0)
    for i in range(last):  # x_{i+1} - F x_i ~ N(0, Q)
        a = np.zeros((n, size))
        a[:, n * i:n * i + n], a[:, n * i + n:n * i + 2 * n] = -f[i], np.eye(n)
        info += a.T @ np.linalg.solve(q[i], a)
    for i in range(last + 1):
        info[n * i:n * i + n, n * i:n * i + n] += factor[i] @ factor[i].T
    return np.linalg.inv(info)


def test_the_filter_and_smoother_are_the_dense_posteriors():
    p0, f, q, factor = _chain()
    filtered, predicted = covariance_filter(p0, f, q, factor)
    smoothed = covariance_smoother(filtered, predicted, f)
    n, k = p0.shape[0], factor.shape[0]
    full = _dense(p0, f, q, factor, k - 1)
    for i in range(k):
        upto = _dense(p0, f, q, factor, i)
        np.testing.assert_allclose(filtered[i], upto[-n:, -n:], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(smoothed[i], full[n * i:n * i + n, n * i:n * i + n], rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(predicted[0], f[0] @ filtered[0] @ f[0].T + q[0], rtol=1e-12)


def test_a_singular_start_is_fine():
    # a state whose prior variance is zero (the heading walk's start) stays a valid filter
    p0, f, q, factor = _chain()
    p0[2, 2] = 0.0
    filtered, _ = covariance_filter(p0, f, q, factor)
    assert filtered[0][2, 2] == 0.0 and np.all(np.linalg.eigvalsh(filtered[1:]) > 0)
