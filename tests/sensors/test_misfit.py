"""The local misfit scale: its prior, its update from residuals, its forgetting, its counts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.sensors import MisfitScale, NavigationModel, misfit_counts


def test_the_prior_states_the_stated_error_and_is_forgotten_back_to():
    prior = MisfitScale.prior(6.0, 50.0)
    assert (prior.shape, prior.rate, prior.factor) == (3.0, 3.0, 1.0)
    later = prior.after(np.array([90.0]), np.array([10.0]), np.array([1.0]))
    assert (later.shape, later.rate) == (8.0, 48.0)
    assert later.forget(0.0) == later
    one = later.forget(50.0)  # one length: the excess over the prior shrinks by 1/e
    assert one.shape == pytest.approx(3.0 + 5.0 / math.e)
    assert one.rate == pytest.approx(3.0 + 45.0 / math.e)
    assert later.forget(1e6) == prior


def test_the_scale_of_a_patch_is_recovered_from_its_residuals():
    """Soundings erring five times the stated variance, 40 pings of 25: the posterior mean of
    the factor is within four of its Monte Carlo standard errors (relative ``sqrt(2 / n)``)."""
    rng = np.random.default_rng(3)
    kappa, n_pings, beams = 5.0, 40, 25
    scale = MisfitScale.prior(4.0, 1e9)
    for _ in range(n_pings):
        squares = kappa * rng.standard_normal(beams) ** 2
        scale = scale.after(np.array([squares.sum()]), np.array([float(beams)]), np.array([1.0]))
    n = n_pings * beams
    assert abs(scale.factor - kappa) < 4 * kappa * math.sqrt(2.0 / n) + kappa * 4.0 / n


def test_the_posterior_weights_average_the_candidates():
    prior = MisfitScale.prior(2.0, 1e9)
    quadratic = np.array([10.0, 50.0, np.nan])
    count = np.array([10.0, 10.0, 10.0])
    both = prior.after(quadratic, count, np.array([1.0, 3.0, 5.0]))  # the NaN one is left out
    assert both.rate == pytest.approx(1.0 + 0.5 * (0.25 * 10 + 0.75 * 50))
    assert prior.after(quadratic, count, np.zeros(3)) == prior


def test_counts_take_out_the_map_error_that_soundings_share():
    """Nine soundings in one spot share one map error (the row-sum bound's ``0.1^2 + 9 *
    0.2^2``): each one's expected whitened square is ``(0.1^2 + 0.2^2) / 0.37``."""
    np.testing.assert_allclose(misfit_counts(np.full(9, 0.37), np.full(9, 0.04), 0.01), 0.05 / 0.37)
    np.testing.assert_array_equal(misfit_counts(np.full(3, 0.25), None, 0.25), 1.0)


@pytest.mark.parametrize("field, value", [("shape", 0.0), ("rate", -1.0), ("dof", math.inf), ("length", 0.0)])
def test_bad_scales_are_refused(field, value):
    fields = {"shape": 1.0, "rate": 1.0, "dof": 2.0, "length": 10.0, field: value}
    with pytest.raises(TangraphError, match=f"MisfitScale.{field} must be a finite number > 0"):
        MisfitScale(**fields)


@pytest.mark.parametrize("field, value", [("misfit_dof", -1.0), ("misfit_length", 0.0)])
def test_the_navigation_model_refuses_bad_misfit_settings(field, value):
    with pytest.raises(TangraphError, match=f"NavigationModel.{field}"):
        NavigationModel(**{field: value})


def test_residuals_smaller_than_stated_do_not_make_the_soundings_more_precise():
    scale = MisfitScale.prior(2.0, 1e9).after(np.array([1.0]), np.array([50.0]), np.array([1.0]))
    assert scale.shape == 26.0 and scale.factor == 1.0


def test_a_map_that_states_its_tail_gives_the_filters_their_prior():
    """The map's ``error_dof`` (from its check lines) wins over the model's ``misfit_dof``, the
    default for a map that states none, as a map's ``depth_std`` wins over ``map_std``."""
    from tangraph.filters.model import FilterModel
    from tangraph.maps import fractal

    chart = fractal((20, 20), 5.0, rng=np.random.default_rng(0))
    stating = chart.replace(error_dof=1.9)
    plain = NavigationModel(sounding_std=0.3)
    assert FilterModel.from_model(plain, chart).misfit_prior() is None
    assert FilterModel.from_model(plain, stating).misfit_prior() == MisfitScale.prior(1.9, 200.0)
    told = NavigationModel(sounding_std=0.3, misfit_dof=4.0, misfit_length=50.0)
    assert FilterModel.from_model(told, chart).misfit_prior() == MisfitScale.prior(4.0, 50.0)
    assert FilterModel.from_model(told, stating).misfit_prior() == MisfitScale.prior(1.9, 50.0)
