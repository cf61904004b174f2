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
    nav = NavigationModel(tide=1.0, tide_std=0.1, tide_drift_std=drift, tide_drift_time=FORGET)
    model = FilterModel.from_model(nav, FLAT)
    belief = model_belief(np.array([250.0, 250.0]), model, 20, rng=np.random.default_rng(0))
    assert belief.tide_var == pytest.approx(0.01 + drift**2)  # the drift's stationary law at the start
    belief = belief.replace(tide=np.linspace(0.0, 2.0, 20), tide_var=0.001)
    first = predict(belief, ping(0, [40.0]), model, rng=np.random.default_rng(1))
    assert first.tide_var == belief.tide_var  # nothing moves before the first ping
    moved = predict(belief, ping(1, [40.0], dt=10.0), model, rng=np.random.default_rng(1))
    keep = np.exp(-10.0 / FORGET) if drift else 1.0
    np.testing.assert_allclose(moved.tide, 1.0 + keep * (belief.tide - 1.0), rtol=1e-12)
    assert moved.tide_var == pytest.approx(keep**2 * 0.001 + (1 - keep**2) * (0.01 + drift**2), rel=1e-12)

    class State:  # what the point-mass filter's prediction reads and writes
        centres = np.zeros((1, 2))
        nodes = np.zeros((1, 2))
        pending = np.zeros((2, 2))
        walk = 0.0
        axes = 1e3 * np.eye(2)  # wide: the DR noise is not convolved in yet
        tide = np.linspace(0.0, 2.0, 20).reshape(1, 4, 5)
        tide_var = 0.001

    state = State()
    _predict(state, ping(1, [40.0], dt=10.0), model)  # type: ignore[arg-type]
    np.testing.assert_allclose(state.tide.ravel(), moved.tide, rtol=1e-12)
    assert state.tide_var == pytest.approx(moved.tide_var, rel=1e-12)


def tide_nees(drift_in_model: float, runs: int, pings: int = 60, noise: float = 0.3,
              beams: int = 3) -> np.ndarray:
    """Final NEES of the tide posterior at the true position over independent runs of a tide
    that drifts by ``DRIFT`` over ``FORGET`` (on a flat map only the tide is learnt)."""
    nav = NavigationModel(sounding_std=noise, tide_std=0.05, tide_drift_std=drift_in_model,
                          tide_drift_time=FORGET)
    model = FilterModel.from_model(nav, FLAT)
    rng = np.random.default_rng(7)
    at = np.array([[250.0, 250.0]])
    keep = np.exp(-2.0 / FORGET)
    out = np.empty(runs)
    for r in range(runs):
        truth = np.hypot(0.05, DRIFT) * rng.standard_normal()
        mean, var = np.zeros(1), nav.tide_variance
        for k in range(pings):
            if k:
                truth = keep * truth + DRIFT * np.sqrt(1 - keep**2) * rng.standard_normal()
            p = ping(k, 40.0 + truth + noise * rng.standard_normal(beams))
            mean, var = model.tide_predict(mean, var, p)
            update = model.terrain.evaluate(at, mean, var, p)
            mean, var = update.tide, update.tide_var
        out[r] = (mean[0] - truth) ** 2 / var
    return out


def test_the_tide_posterior_follows_a_drifting_tide_within_its_stated_variance():
    runs = 300
    nees = tide_nees(DRIFT, runs)
    low, high = stats.chi2.ppf([0.005, 0.995], runs) / runs  # the mean NEES's 99 % band
    assert low <= nees.mean() <= high
    assert tide_nees(0.0, runs).mean() > 5.0 * high  # a constant tide claims what it does not know
