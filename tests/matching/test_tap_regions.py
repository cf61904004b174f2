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
