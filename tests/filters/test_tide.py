"""The tide's drift (``NavigationModel.tide_drift_std``, ``tide_drift_time``) in the filters:
between pings every filter's tide posterior reverts towards the prior as a Gauss-Markov
process does, and with it the posterior follows a drifting tide (its NEES in the chi-square
band over independent runs), where a constant tide is over-confident."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

from tangraph.errors import TangraphError
from tangraph.filters.belief import model_belief
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.pmf import _predict
from tangraph.filters.steps import predict
from tangraph.filters.tide import TideDrift, predict_tide, update_drift
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel

FLAT = BathymetryMap(north=np.arange(0.0, 500.0, 10.0), east=np.arange(0.0, 500.0, 10.0),
                     depth=np.full((50, 50), 40.0), name="flat")
DRIFT, FORGET = 0.3, 40.0  # m, s


def ping(index: int, depths, dt: float = 2.0) -> Ping:
    depths = np.asarray(depths, float)
    return Ping(index, np.zeros(2), np.zeros((depths.size, 2)), depths, first=index == 0,
                dt=0.0 if index == 0 else dt)


def test_the_tide_drift_is_a_model_field_checked_like_the_others():
    model = NavigationModel.from_mapping({"tide_std": 0.1, "tide_drift_std": 0.2, "tide_drift_time": 100.0})
    assert model.tide_variance == pytest.approx(0.05)
    assert model.tide_memory(100.0) == pytest.approx(np.exp(-1.0))
    assert NavigationModel().tide_memory(100.0) == 1.0  # no drift: the tide is kept
    with pytest.raises(TangraphError, match="tide_drift_std must be >= 0"):
        NavigationModel(tide_drift_std=-0.1, tide_drift_time=10.0)
    with pytest.raises(TangraphError, match="tide_drift_time must be > 0 s with tide_drift_std = 0.2 m"):
        NavigationModel(tide_drift_std=0.2)


@pytest.mark.parametrize("drift", [0.0, DRIFT])
def test_every_filter_carries_its_tide_posterior_through_the_drift(drift):
    """The datum and the drift as one Gaussian: the means moved by ``A``, the covariance to
    ``A P A^T + Q`` (module :mod:`tangraph.filters.tide`), the same in the particle filters'
    prediction and the point-mass filter's; nothing moves without a drift."""
    nav = NavigationModel(tide=1.0, tide_std=2.0, tide_drift_std=drift, tide_drift_time=FORGET)
    model = FilterModel.from_model(nav, FLAT)
    belief = model_belief(np.array([250.0, 250.0]), model, 20, rng=np.random.default_rng(0))
    assert belief.tide_var == pytest.approx(4.0 + drift**2)  # the datum's prior and the drift's
    if not drift:
        assert belief.tide_drift is None
        moved = predict(belief, ping(1, [40.0], dt=10.0), model, rng=np.random.default_rng(1))
        assert moved.tide_var == belief.tide_var and np.array_equal(moved.tide, belief.tide)
        return
    assert belief.tide_drift.cross == belief.tide_drift.var == pytest.approx(drift**2)
    state = TideDrift(np.linspace(-0.5, 0.5, 20), 0.02, 0.05)
    belief = belief.replace(tide=np.linspace(0.0, 2.0, 20), tide_var=0.3, tide_drift=state)
    first = predict(belief, ping(0, [40.0]), model, rng=np.random.default_rng(1))
    assert first.tide_var == belief.tide_var and first.tide_drift is state  # nothing before the first ping
    moved = predict(belief, ping(1, [40.0], dt=10.0), model, rng=np.random.default_rng(1))
    keep = np.exp(-10.0 / FORGET)
    a = np.array([[1.0, keep - 1.0], [0.0, keep]])
    cov = a @ np.array([[0.3, 0.02], [0.02, 0.05]]) @ a.T + drift**2 * (1 - keep**2) * np.ones((2, 2))
    means = np.column_stack([belief.tide, state.mean]) @ a.T
    np.testing.assert_allclose(moved.tide, means[:, 0], rtol=1e-12)
    np.testing.assert_allclose(moved.tide_drift.mean, means[:, 1], rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose([moved.tide_var, moved.tide_drift.cross, moved.tide_drift.var],
                               [cov[0, 0], cov[0, 1], cov[1, 1]], rtol=1e-12)

    class State:  # what the point-mass filter's prediction reads and writes
        centres = np.zeros((1, 2))
        nodes = np.zeros((1, 2))
        pending = np.zeros((2, 2))
        walk = 0.0
        axes = 1e3 * np.eye(2)  # wide: the DR noise is not convolved in yet
        tide = np.linspace(0.0, 2.0, 20).reshape(1, 4, 5)
        tide_var = 0.3
        tide_drift = TideDrift(np.linspace(-0.5, 0.5, 20).reshape(1, 4, 5), 0.02, 0.05)
        point_cal = None  # the bank's state

    grid = State()
    _predict(grid, ping(1, [40.0], dt=10.0), model)  # type: ignore[arg-type]
    np.testing.assert_allclose(grid.tide.ravel(), moved.tide, rtol=1e-12)
    np.testing.assert_allclose(grid.tide_drift.mean.ravel(), moved.tide_drift.mean, rtol=1e-12, atol=1e-15)
    assert grid.tide_var == pytest.approx(moved.tide_var, rel=1e-12)


def test_the_soundings_move_the_drift_as_the_joint_kalman_update_does():
    """The soundings tell the whole offset only; the drift's posterior by its regression on it
    equals the two-state Kalman update with ``H = [1, 0]`` on the same soundings."""
    nav = NavigationModel(tide_std=2.0, sounding_std=0.3, map_std=0.0, tide_drift_std=DRIFT,
                          tide_drift_time=FORGET)
    model = FilterModel.from_model(nav, FLAT)
    prior_mean, prior_cov = np.array([0.4, -0.1]), np.array([[1.2, 0.05], [0.05, 0.07]])
    depths = 40.0 + np.array([0.9, 1.3, 1.1])
    update = model.terrain.evaluate(np.array([[250.0, 250.0]]), prior_mean[:1], prior_cov[0, 0],
                                    ping(1, depths))
    drift = update_drift(TideDrift(prior_mean[1:], prior_cov[0, 1], prior_cov[1, 1]), prior_mean[:1],
                         prior_cov[0, 0], update.tide, update.tide_var)
    h = np.ones((3, 1)) @ np.array([[1.0, 0.0]])
    r = 0.3**2 * np.eye(3)
    gain = prior_cov @ h.T @ np.linalg.inv(h @ prior_cov @ h.T + r)
    mean = prior_mean + gain @ (depths - 40.0 - h @ prior_mean)
    cov = (np.eye(2) - gain @ h) @ prior_cov
    np.testing.assert_allclose([update.tide[0], drift.mean[0]], mean, rtol=1e-9)
    np.testing.assert_allclose([update.tide_var, drift.cross, drift.var], [cov[0, 0], cov[0, 1], cov[1, 1]],
                               rtol=1e-9)


def tide_nees(drift_in_model: float, runs: int, tide_std: float = 0.05, pings: int = 60,
              noise: float = 0.3, beams: int = 3) -> np.ndarray:
    """Final NEES of the tide posterior at the true position over independent runs of a datum
    drawn from ``N(0, tide_std^2)`` and a tide that drifts about it by ``DRIFT`` over ``FORGET``
    (on a flat map only the tide is learnt)."""
    nav = NavigationModel(sounding_std=noise, tide_std=tide_std, tide_drift_std=drift_in_model,
                          tide_drift_time=FORGET)
    model = FilterModel.from_model(nav, FLAT)
    rng = np.random.default_rng(7)
    at = np.array([[250.0, 250.0]])
    keep = np.exp(-2.0 / FORGET)
    out = np.empty(runs)
    for r in range(runs):
        datum, drift = tide_std * rng.standard_normal(), DRIFT * rng.standard_normal()
        mean, var, state = np.zeros(1), nav.tide_variance, TideDrift.start(nav, 1)
        for k in range(pings):
            if k:
                drift = keep * drift + DRIFT * np.sqrt(1 - keep**2) * rng.standard_normal()
            p = ping(k, 40.0 + datum + drift + noise * rng.standard_normal(beams))
            mean, var, state = predict_tide(mean, var, state, nav, p)
            update = model.terrain.evaluate(at, mean, var, p)
            state = update_drift(state, mean, var, update.tide, update.tide_var)
            mean, var = update.tide, update.tide_var
        out[r] = (mean[0] - datum - drift) ** 2 / var
    return out


@pytest.mark.parametrize("tide_std", [0.05, 3.0])
def test_the_tide_posterior_follows_a_drifting_tide_within_its_stated_variance(tide_std):
    """With a datum known to centimetres or only to metres: the datum learnt is kept while the
    drift about it is followed."""
    runs = 300
    nees = tide_nees(DRIFT, runs, tide_std)
    low, high = stats.chi2.ppf([0.005, 0.995], runs) / runs  # the mean NEES's 99 % band
    assert low <= nees.mean() <= high
    assert tide_nees(0.0, runs, tide_std).mean() > 5.0 * high  # a constant tide claims what it does not know


def test_the_point_mass_filter_mixes_and_regrids_the_datum_and_the_drift_together():
    """Convolving the DR noise into the density mixes neighbouring points' tide posteriors: the
    mass-weighted first and second moments of the offset and of its drift (their cross moment
    too) are kept, the spread of the mixed means going into the shared covariance; a re-grid
    interpolates both means (a constant stays that constant)."""
    from tangraph.filters.config import PMFConfig
    from tangraph.filters.pmf import _start
    from tangraph.filters.pmf_grid import _diffuse, _Grid, _regrid

    nav = NavigationModel(tide_std=2.0, tide_drift_std=DRIFT, tide_drift_time=FORGET, speed_scale_std=0.0,
                          heading_bias_std=0.0, initial_position_std=20.0)
    config = PMFConfig()
    grid = _Grid(config, config.min_spacing)
    state = _start(nav, np.array([250.0, 250.0]), grid, config)
    i, j = np.meshgrid(np.arange(state.n), np.arange(state.n), indexing="ij")  # means that vary smoothly
    state.tide = (1.0 + 0.05 * i - 0.02 * j)[None]
    state.tide_drift = TideDrift((0.03 * j - 0.1)[None], 0.02, 0.05)
    state.tide_var = 0.3

    def moments(s):
        p = np.exp(s.log_density - s.log_density.max())
        w = p / p.sum()
        t, d = s.tide, s.tide_drift.mean
        return np.array([np.sum(w * t), np.sum(w * d), s.tide_var + np.sum(w * t * t),
                         s.tide_drift.var + np.sum(w * d * d), s.tide_drift.cross + np.sum(w * t * d)])

    before = moments(state)
    state.pending = np.diag([9.0, 4.0])  # a few grid spacings: the means mix
    _diffuse(state)
    np.testing.assert_allclose(moments(state), before, rtol=1e-6, atol=1e-9)
    assert state.tide_var > 0.3 and state.tide_drift.var > 0.05
    state.tide_drift = TideDrift(np.full(state.tide.shape, 0.7), state.tide_drift.cross, state.tide_drift.var)
    moved = _regrid(state, grid, config, estimate=False)
    live = np.exp(moved.log_density) > 1e-12
    np.testing.assert_allclose(moved.tide_drift.mean[live], 0.7, rtol=1e-9)
    assert moved.tide_drift.var == state.tide_drift.var
