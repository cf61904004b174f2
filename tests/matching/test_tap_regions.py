"""A fix's regions and covariances (tangraph.matching.tap_regions): the larger of two covariances
in every direction; the regions themselves are tested through ``tap_fix`` in test_tap.py."""

from __future__ import annotations

import numpy as np


def test_larger_covariance_is_the_larger_in_every_direction():
    from tangraph.matching.tap_regions import _larger

    np.testing.assert_allclose(_larger(np.diag([1.0, 4.0]), np.diag([4.0, 1.0])), np.diag([4.0, 4.0]))
    a = np.array([[2.0, 0.5], [0.5, 1.0]])
    np.testing.assert_allclose(_larger(a, 0.1 * a), a)
    infinite = np.full((2, 2), np.inf)  # an uninformative window's (the CRLB's when singular)
    assert np.array_equal(_larger(infinite, a), infinite)
    assert np.array_equal(_larger(a, infinite), a)


def test_larger_of_a_singular_covariance_is_taken_in_the_others_whitening():
    """A region flat along one axis of the search gives a singular covariance; the larger of it
    and a proper one (the map error's sandwich) is positive definite and at least both (a
    window of Lake Caputh's long run gave these two)."""
    from tangraph.matching.tap_regions import _larger

    region = np.array([[148.68, 0.0], [0.0, 0.0]])
    shared = np.array([[22.82, -25.97], [-25.97, 107.31]])
    for out in (_larger(region, shared), _larger(shared, region)):
        assert np.linalg.eigvalsh(out).min() > 0
        for part in (region, shared):
            assert np.linalg.eigvalsh(out - part).min() > -1e-9
    np.testing.assert_allclose(_larger(region, shared), _larger(shared, region), rtol=1e-9)
    flat = np.diag([1.0, 0.0])
    np.testing.assert_allclose(_larger(flat, np.diag([0.0, 2.0])), np.diag([1.0, 2.0]))  # neither: the sum
