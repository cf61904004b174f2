"""The point-mass filter's calibration bank: the nodes and the cells they stand for keep the
calibration's Gaussian, and what a cell's calibrations and the heading walk do to a member's
positions (:class:`~tangraph.filters.pmf_bank.CellSpread`) against Monte Carlo."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.filters.pmf_bank import CellSpread, _cell_share, _place_nodes
from tangraph.geometry import rotate


@pytest.mark.parametrize("counts", [(3, 3), (1, 5), (5, 1), (1, 1)])
def test_the_nodes_and_their_cells_keep_the_gaussian(counts):
    """The members' nodes (weighted) plus the cell each stands for: the mean and covariance."""
    mean = np.array([0.01, -0.02])
    cov = np.array([[4e-4, 3e-5], [3e-5, 2.5e-3]])
    nodes, log_w, cell = _place_nodes(mean, cov, counts)
    w = np.exp(log_w)
    np.testing.assert_allclose(w.sum(), 1.0)
    np.testing.assert_allclose(w @ nodes, mean, atol=1e-12)
    d = nodes - mean
    np.testing.assert_allclose((d * w[:, None]).T @ d + cell, cov, rtol=1e-9, atol=1e-12)
    assert np.all(np.linalg.eigvalsh(cell) >= -1e-15)
    if counts == (1, 1):  # one node stands for the whole Gaussian
        np.testing.assert_allclose(cell, cov, rtol=1e-12)


def test_a_cell_is_as_wide_as_its_nodes_spacing():
    assert _cell_share(1) == 1.0
    assert _cell_share(3) == pytest.approx(3.0 / 12.0)
    assert 0.0 < _cell_share(7) < _cell_share(5) < _cell_share(3)


def _positions(steps, k, b, walks):
    """Endpoints of ``sum R(-(b + w_i)) u_i / (1 + k)`` for draws ``k (D,)``, ``b (D,)`` and the
    heading walk's cumulative changes ``walks (D, S)`` (the walk of step i moves it and after)."""
    heading = b[:, None] + walks  # (D, S)
    moved = rotate(-heading, steps[None, :, :]) / (1.0 + k)[:, None, None]
    return moved.sum(axis=1)


@pytest.mark.parametrize("turn", [False, True])
def test_the_cell_spread_is_the_positions_spread(turn):
    """Calibrations drawn from a cell and heading walks drawn at each step: the covariance of the
    positions they give is the spread the steps convolved in, within Monte Carlo error on a
    straight line, and no more than it after a U-turn (the spread is never taken back)."""
    rng = np.random.default_rng(2)
    n_steps, draws = 60, 200_000
    steps = np.tile([2.0, 0.5], (n_steps, 1))
    if turn:
        steps[n_steps // 2:] *= -1.0
    walk = np.full(n_steps, np.radians(0.3) ** 2)
    centre = np.array([0.02, np.radians(3.0)])
    cell = np.array([[1e-4, 2e-5], [2e-5, np.radians(2.0) ** 2]])
    spread, total = CellSpread(cell), np.zeros((2, 2))
    for u, v in zip(steps, walk, strict=True):
        spread, new = spread.step(u, v, centre)
        total += new
    np.testing.assert_allclose(total, spread.applied)
    c = rng.multivariate_normal(centre, cell, draws)
    walks = np.cumsum(np.sqrt(walk) * rng.standard_normal((draws, n_steps)), axis=1)
    walks = np.concatenate([np.zeros((draws, 1)), walks[:, :-1]], axis=1)  # after its step
    end = _positions(steps, c[:, 0], c[:, 1], walks)
    sample = np.cov(end.T)
    sd = np.sqrt(np.diag(sample))
    if not turn:
        np.testing.assert_allclose(total, sample, atol=0.03 * np.outer(sd, sd).max())
    else:
        assert np.all(np.linalg.eigvalsh(total - sample) > -0.03 * sd.max() ** 2)
        assert np.trace(total) > 1.5 * np.trace(sample)  # what the way out spread is kept
