"""The point-mass filter's shortcuts against the plain computations they replace: a ping weighs
only the points of nonzero density (the same posterior as weighing every point), the support
from the grid's rows and columns, and the derived values a state caches (the members' moments
among them; dropped when a field they come from is replaced)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.filters import PMFConfig, pmf
from tangraph.filters.likelihood import log_normalise
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.pmf_grid import _extent, _significant
from tangraph.maps import fractal
from tangraph.sensors import MisfitScale, NavigationModel, slope_moment


def _case(misfit: bool):
    """A rough map with a hole (some points have no map under a sounding), a ping of 41
    soundings, the start state of a 3 x 3 bank (tide uncertain) moved off the truth, with a band
    of zero density and a misfit scale if asked."""
    chart = fractal((121, 121), 5.0, rng=np.random.default_rng(3), relief=8.0, mean_depth=50.0)
    depth = chart.depth.copy()
    depth[50:70, 70:74] = np.nan
    chart = dataclasses.replace(chart, depth=depth)
    model = NavigationModel(sounding_std=0.3, tide_std=0.5, heading_bias_std=0.02, speed_scale_std=0.01)
    filter_model = FilterModel.from_model(model, chart)
    across = np.linspace(-60.0, 60.0, 41)
    ping = Ping(3, np.array([2.0, 0.0]), np.column_stack([np.zeros(41), across]),
                chart.depth_at(np.full(41, 300.0), 300.0 + across) + 0.2, dt=1.0)
    config = PMFConfig(grid_points=15, calibration="bank")
    state = pmf._start(model, np.array([296.0, 303.0]), pmf._Grid(config, config.min_spacing), config)
    density = state.log_density.copy()
    density[:, :4, :] = -np.inf  # a band no mass has reached
    density[2] = -np.inf  # and a member of no mass
    state.log_density = density
    state.tide = state.tide + np.random.default_rng(4).normal(0.0, 0.1, state.tide.shape)
    if misfit:
        state.misfit = MisfitScale.prior(5.0, 200.0)
    return state, ping, filter_model, slope_moment(chart)


def _every_point(state, ping, model, slope):
    """The ping weighed at every point (the plain computation): the posterior log density, tide
    means, tide variance and misfit scale."""
    points = state.points()
    log_mass = (state.log_density - np.max(state.log_density)).ravel()
    weights = np.exp(log_mass)
    resolution = float(np.trace(state.axes.T @ slope @ state.axes)) / 12.0
    update = model.terrain.evaluate(points, state.tide.ravel(), state.tide_var, ping,
                                    np.repeat(state.nodes[:, 1], state.n**2), weights=weights,
                                    scale=state.misfit, extra_variance=resolution)
    posterior = state.log_density.ravel() + update.log_likelihood
    _, log_total = log_normalise(posterior)
    density = posterior - log_total - np.log(state.cell_area)
    misfit = update.scale_after(np.exp(posterior - np.max(posterior)))
    return density, update.tide, update.tide_var, misfit


@pytest.mark.parametrize("misfit", [False, True])
def test_weighing_the_points_of_nonzero_density_is_weighing_every_point(misfit):
    state, ping, model, slope = _case(misfit)
    density, tide, tide_var, scale = _every_point(state, ping, model, slope)
    before = state.tide.ravel().copy()
    check, update = pmf._update(state, ping, model, slope)
    assert check is not None and update is not None
    assert 0.0 < np.mean(update.mapped < 1.0) < 0.5  # some weighed points miss the map
    out = state.log_density.ravel()
    live = np.isfinite(density)
    assert live.sum() < 0.8 * live.size  # the case has points of zero density
    np.testing.assert_array_equal(np.isfinite(out), live)
    np.testing.assert_allclose(out[live], density[live], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(state.tide.ravel()[live], tide[live], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(state.tide.ravel()[~live], before[~live])  # kept
    np.testing.assert_allclose(state.tide_var, tide_var, rtol=1e-12)
    if misfit:
        np.testing.assert_allclose([state.misfit.shape, state.misfit.rate], [scale.shape, scale.rate],
                                   rtol=1e-12)


def test_the_member_moments_are_the_plain_sums():
    state = _case(False)[0]
    density = state.log_density.copy()
    density[0] += np.linspace(0.0, 3.0, state.n)[None, :]  # a skewed member
    state.log_density = density
    weight, mean, cov = state.member_moments()
    mass = state.masses().reshape(len(state.nodes), -1)
    offsets = state.offsets()
    np.testing.assert_allclose(weight, mass.sum(axis=1), rtol=1e-12)
    for m in range(len(state.nodes)):
        if weight[m] == 0:  # no mass: its centre and no spread
            np.testing.assert_array_equal(mean[m], state.centres[m])
            np.testing.assert_array_equal(cov[m], 0.0)
            continue
        w = mass[m] / weight[m]
        local = w @ offsets
        d = offsets - local
        np.testing.assert_allclose(mean[m], state.centres[m] + local, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(cov[m], (d * w[:, None]).T @ d, rtol=1e-10, atol=1e-12)


def test_the_support_from_rows_and_columns_is_the_pointwise_extent():
    state = _case(False)[0]
    for shift in (0.0, 0.3, 2.7):  # the density moved across its grid
        density = state.log_density.copy()
        density -= 0.5 * shift * np.arange(state.n)[None, :, None]
        state.log_density = density
        i, j = np.meshgrid(np.arange(state.n), np.arange(state.n), indexing="ij")
        index = np.column_stack([i.ravel(), j.ravel()]).astype(np.float64)
        mass = state.masses().reshape(len(state.nodes), -1)
        weight = mass.sum(axis=1, keepdims=True)
        centre = (mass @ index) / np.where(weight > 0, weight, 1.0)
        pointwise = _extent((index[None] - centre[:, None]).reshape(-1, 2), mass.ravel())
        np.testing.assert_array_equal(_significant(state), pointwise)


def test_cached_values_follow_the_fields_and_are_read_only():
    state = _case(False)[0]
    masses, moments = state.masses(), state.member_moments()
    assert state.masses() is masses and not masses.flags.writeable
    trial = state.copy()
    assert trial.masses() is masses  # a copy starts with the same values
    trial.centres = trial.centres + 1.0
    assert trial.masses() is masses  # the density has not changed
    np.testing.assert_allclose(trial.member_moments()[1], moments[1] + 1.0)
    assert state.member_moments() is moments  # the copy's fields are its own
    trial.log_density = trial.log_density + np.log(2.0)
    assert trial.masses() is not masses
    np.testing.assert_allclose(trial.member_log_mass(), state.member_log_mass() + np.log(2.0))
    with pytest.raises(ValueError):
        masses[0, 0, 0] = 1.0
