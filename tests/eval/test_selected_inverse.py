"""Tests of the sparse LDL^T and the selected inverse: against the dense inverse on random sparse
positive definite matrices, entries asked for through explicit zeros, the trailing block alone, and
a matrix that is not positive definite."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import sparse

from tangraph.errors import TangraphError
from tangraph.eval.selected_inverse import factor, fill_reducing_order, inverse_entries, selected_inverse


def _spd(n: int, seed: int, zeros=()) -> sparse.csc_array:
    """A random sparse positive definite matrix, with explicit zeros at the pairs ``zeros``."""
    rng = np.random.default_rng(seed)
    b = sparse.random_array((n, n), density=3.0 / n, rng=rng)
    a = sparse.coo_array(b @ b.T + 0.1 * sparse.eye_array(n))
    r, c = np.array(zeros, dtype=np.int64).reshape(-1, 2).T
    rows = np.concatenate([a.row, r, c])
    cols = np.concatenate([a.col, c, r])
    values = np.r_[a.data, np.zeros(2 * r.size)]
    return sparse.csc_array(sparse.coo_array((values, (rows, cols)), shape=(n, n)))


@pytest.mark.parametrize("seed", [0, 1])
def test_the_selected_inverse_is_the_inverse_on_the_matrixs_pattern(seed):
    pairs = [(0, 199), (3, 150), (42, 43)]
    a = _spd(200, seed, pairs)
    want = np.linalg.inv(a.toarray())
    f = factor(a, fill_reducing_order(a))
    assert f.data.size < 0.5 * 200 * 199 / 2  # the order keeps the factor sparse
    z = selected_inverse(f)
    coo = sparse.coo_array(a)
    got = inverse_entries(f, z, coo.row, coo.col)
    np.testing.assert_allclose(got, want[coo.row, coo.col], rtol=1e-9, atol=1e-12 * np.abs(want).max())
    r, c = np.array(pairs).T
    np.testing.assert_allclose(inverse_entries(f, z, r, c), want[r, c], rtol=1e-9)
    np.testing.assert_allclose(inverse_entries(f, z, c, r), want[r, c], rtol=1e-9)
    np.testing.assert_allclose(np.diag(want)[f.order], z[0], rtol=1e-9)


def test_the_trailing_block_alone_and_in_the_natural_order():
    a = _spd(120, 5, [(7, 119)])
    want = np.linalg.inv(a.toarray())
    order = np.r_[np.setdiff1d(np.arange(120), [7, 119]), 7, 119]  # the two asked for last
    f = factor(a, order)
    z = selected_inverse(f, first=118)
    got = inverse_entries(f, z, np.array([[7], [119]]), np.array([[7, 119]]))
    np.testing.assert_allclose(got, want[np.ix_([7, 119], [7, 119])], rtol=1e-9)
    assert np.all(z[0][:118] == 0.0)


def test_an_entry_off_the_pattern_and_a_matrix_not_positive_definite_are_refused():
    a = sparse.csc_array(np.diag([1.0, 2.0, 3.0]))
    f = factor(a, np.arange(3))
    z = selected_inverse(f)
    np.testing.assert_allclose(inverse_entries(f, z, np.arange(3), np.arange(3)), [1.0, 0.5, 1 / 3])
    with pytest.raises(TangraphError, match="not on the factor's pattern"):
        inverse_entries(f, z, np.array([0]), np.array([2]))
    with pytest.raises(TangraphError, match="not positive definite"):
        factor(sparse.csc_array(np.array([[1.0, 2.0], [2.0, 1.0]])), np.arange(2))
