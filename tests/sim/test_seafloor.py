"""The true seafloor of a world whose seafloor is not the map (:mod:`tangraph.sim.seafloor`): its
random field, and the patches in which that field's std varies."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap
from tangraph.sim.seafloor import SeafloorSettings, true_seafloor

AXIS = np.arange(0.0, 4000.0, 10.0)
FLAT = BathymetryMap(AXIS, AXIS, np.full((AXIS.size, AXIS.size), 30.0), name="flat")
TRACK = np.array([[1000.0, 1000.0], [3000.0, 3000.0]])


def _error(settings: SeafloorSettings, seed: int = 4) -> np.ndarray:
    seafloor = true_seafloor(FLAT, TRACK, settings, rng=np.random.default_rng(seed))
    return seafloor.depth - 30.0


def test_without_patches_the_field_is_gaussian_and_unchanged_by_the_patch_settings():
    plain = _error(SeafloorSettings(std=0.3, correlation_length=30.0))
    np.testing.assert_array_equal(plain, _error(SeafloorSettings(std=0.3, patch_length=50.0)))
    z = plain / plain.std()
    assert plain.std() == pytest.approx(0.3, rel=0.05)
    assert np.mean(z**4) == pytest.approx(3.0, abs=0.3)  # Gaussian kurtosis


def test_patches_keep_the_mean_square_and_give_the_field_a_heavy_tail():
    """A log-std of 1 over patches of 300 m: the field's kurtosis is about ``3 exp(4)`` in
    expectation (far above a Gaussian's 3 in any draw), its RMS stays near ``std`` (the
    factor's mean square is 1; a map of a few patches scatters about it), and the worst 5 % of
    100 m squares err several times more than the median square (``exp(1.645)``, 5.2, for a
    factor constant over a square; measured 3.9-6.5 over eight seeds)."""
    rms, kurtosis, spread = [], [], []
    for seed in range(4):
        error = _error(SeafloorSettings(std=0.3, correlation_length=30.0, patch_scale_std=1.0,
                                        patch_length=300.0), seed)
        rms.append(np.sqrt(np.mean(error**2)))
        kurtosis.append(np.mean(error**4) / np.mean(error**2) ** 2)
        n = error.shape[0] // 10 * 10
        squares = error[:n, :n].reshape(n // 10, 10, n // 10, 10).std(axis=(1, 3)).ravel()
        spread.append(np.quantile(squares, 0.95) / np.median(squares))
    assert 0.15 < np.sqrt(np.mean(np.square(rms))) < 0.6
    assert min(kurtosis) > 10.0
    assert min(spread) > 3.0


def test_a_negative_patch_scale_is_refused():
    with pytest.raises(TangraphError, match="patch_scale_std"):
        SeafloorSettings.from_table({"patch_scale_std": -1.0}, "scenario [seafloor]")
