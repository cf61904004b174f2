"""The resampling schemes (tangraph.filters.resampling): one particle with all the weight, equal
weights, mean counts N times the weights; a bad draw count or scheme refused."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters.resampling import Resampler, resample


@pytest.mark.parametrize("scheme", list(Resampler))
def test_one_particle_with_all_the_weight(scheme):
    w = np.array([0.0, 0.0, 1.0, 0.0])
    idx = resample(w, scheme, rng=np.random.default_rng(0))
    assert idx.tolist() == [2, 2, 2, 2]
    assert w.tolist() == [0.0, 0.0, 1.0, 0.0]  # not modified


@pytest.mark.parametrize("scheme", [Resampler.SYSTEMATIC, Resampler.STRATIFIED, Resampler.RESIDUAL])
def test_equal_weights_keep_every_particle_once(scheme):
    assert sorted(resample(np.full(10, 0.1), scheme, rng=np.random.default_rng(1))) == list(range(10))


@pytest.mark.parametrize("scheme", list(Resampler))
def test_mean_counts_are_n_times_the_weights(scheme):
    w = np.array([0.05, 0.15, 0.3, 0.5])
    n, runs = 40, 400
    rng = np.random.default_rng(5)
    counts = np.array([np.bincount(resample(w, scheme, rng=rng, n=n), minlength=4) for _ in range(runs)])
    if scheme in (Resampler.SYSTEMATIC, Resampler.RESIDUAL):  # each count within floor/ceil of N w
        assert np.all(counts >= np.floor(n * w)) and np.all(counts <= np.ceil(n * w))
    standard_error = np.sqrt(n * w * (1 - w) / runs)  # multinomial bound on the others' scatter
    assert np.all(np.abs(counts.mean(axis=0) - n * w) < 4 * standard_error)


@pytest.mark.parametrize("n", [0, -3, 2.5, True])
def test_resample_needs_at_least_one_draw(n):
    with pytest.raises(TangraphError, match=f"resample: n must be an integer >= 1, got {n!r}"):
        resample([0.5, 0.5], "systematic", rng=np.random.default_rng(0), n=n)


def test_resample_names_an_unknown_scheme():
    with pytest.raises(TangraphError, match="resample: scheme must be one of .*got 'bogus'"):
        resample([0.5, 0.5], "bogus", rng=np.random.default_rng(0))
