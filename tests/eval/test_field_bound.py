"""Tests of the map-aware bound's joint solve (tangraph.eval.field_bound): a vanishing field tends
to the bound without it; on a planar seabed it equals a dense linear-Gaussian solve with the
field's covariance among all soundings; the field never lowers the bound, and a long-range field
shared by two passes of one line keeps the second pass from halving the first's variance; the
filter bound is never below the smoother's; the map's offset is an unknown the slope shows as the
vehicle's position; solved on the nodes near the footprints it is the bound on the whole grid."""

from __future__ import annotations

import numpy as np
import pytest

import tangraph.eval.field_bound as field_bound
import tangraph.eval.map_field as map_field
from tangraph.eval import bound_rmse, posterior_crb
from tangraph.eval.map_field import map_error_field
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel, map_error
from tangraph.survey import Survey
from tests.eval.crb_cases import FIELD, MODEL, SLOPE, _design, _seabed, _soundings, _survey


@pytest.mark.parametrize("kind", ["smoother", "filter"])
def test_the_bound_on_the_trimmed_grid_is_the_bound_on_the_whole(kind, monkeypatch):
    # An L-shaped track leaves most of its box empty: the bound is solved on the nodes near it
    # (posterior_crb trims) and equals the bound on every node of the box within 1e-4.
    t = np.arange(300.0)
    north = np.where(t < 150, 100 + 4 * t, 700.0)
    east = np.where(t < 150, 100.0, 100 + 4 * (t - 150))
    truth = np.column_stack([north, east, np.where(t < 150, 0.0, np.pi / 2)])
    offset = np.tile(np.linspace(-20.0, 20.0, 9), (t.size, 1))
    survey = Survey(time=t, dr_pose=truth, vehicle_depth=0 * t, beam_forward=0 * offset,
                    beam_starboard=offset, beam_depth=25 + 0 * offset, true_pose=truth)
    seabed = _seabed()
    model = FIELD.replace(map_correlation_length=30.0)
    trimmed = posterior_crb(survey, seabed, model, kind=kind)
    original = map_field.map_error_field
    monkeypatch.setattr(map_field, "map_error_field", lambda *a, **k: original(*a, **{**k, "trim": False}))
    whole = posterior_crb(survey, seabed, model, kind=kind)
    assert trimmed.field_nodes < 0.6 * whole.field_nodes
    np.testing.assert_allclose(trimmed.position_cov, whole.position_cov, rtol=1e-4,
                               atol=1e-6 * np.abs(whole.position_cov).max())


@pytest.mark.parametrize("kind", ["smoother", "filter"])
def test_a_vanishing_field_tends_to_the_bound_without_it(kind):
    survey, seabed = _survey(), _seabed()
    old = posterior_crb(survey, seabed, MODEL, kind=kind)
    gaps = []
    for std in (0.3, 0.03, 3e-3, 3e-7):
        got = posterior_crb(survey, seabed, FIELD.replace(map_std=std), kind=kind)
        assert got.map_error and got.field_nodes > 0
        gaps.append(np.max(np.abs(got.position_cov - old.position_cov)) / np.abs(old.position_cov).max())
    assert gaps[0] > 1e-2 and np.all(np.diff(gaps) < 0)
    assert gaps[-1] < 1e-9  # the joint sparse solve holds the same DR model as the Kalman filter
    assert got.tide_std == pytest.approx(old.tide_std, rel=1e-9)
    np.testing.assert_allclose(got.calibration_cov, old.calibration_cov, rtol=1e-8)


def test_a_dead_reckoning_without_speed_noise_is_bounded_through_a_tiny_step_variance():
    # An exact constraint cannot enter the information matrix: the step gets the variance
    # field_bound.ZERO_VARIANCE in natural units, about that much times the pings off, relatively.
    model = MODEL.replace(heading_noise=0.0, heading_walk=0.0, speed_noise=0.0)
    survey, seabed = _survey(), _seabed()
    old = posterior_crb(survey, seabed, model)
    got = posterior_crb(survey, seabed, model.replace(map_std=3e-7, map_correlation_length=60.0))
    np.testing.assert_allclose(got.position_cov, old.position_cov, rtol=1e-5)


def test_the_bound_equals_a_dense_solve_with_the_fields_covariance_among_all_soundings():
    # The linear-Gaussian model on a plane: every sounding's row on the DR inputs, and the noise of
    # all soundings together, sounding_std^2 I + diag(nugget) + (W S) Q^-1 (W S)^T, with the field's
    # own nodes, precision Q, node stds S and interpolation weights W. Smoother: the whole survey;
    # filter: the soundings of pings up to k (their noise's marginal is the principal block).
    survey, seabed, model = _survey(), _seabed(), FIELD
    a, e, tide_row, var = _design(survey, model)
    used, turn = _soundings(survey, seabed)
    ping, _ = np.nonzero(used)
    h = -(np.array(SLOPE) @ a)[ping] - turn[used][:, None] * e[ping] + tide_row
    north, east = survey.footprints(survey.true_pose)
    field = map_error_field(north[used], east[used], map_error(seabed, model), trim=True)  # the bound's
    assert 100 < field.n_nodes < 2000
    node, weight = field.weights(north[used], east[used])
    w = np.zeros((h.shape[0], field.n_nodes))
    np.add.at(w, (np.arange(h.shape[0])[:, None], node), weight * field.std[node])
    noise = (np.diag(model.sounding_std**2 + field.nugget(node, weight))
             + w @ np.linalg.inv(field.precision.toarray()) @ w.T)
    keep = var > 0
    a, h, var = a[:, :, keep], h[:, keep], var[keep]

    def covariance(rows):
        info = np.diag(1 / var) + h[rows].T @ np.linalg.solve(noise[np.ix_(rows, rows)], h[rows])
        return np.linalg.inv(info)

    full = covariance(np.arange(h.shape[0]))
    smoother = np.einsum("kap,pq,kbq->kab", a, full, a)
    filt = np.array([a[k] @ covariance(np.flatnonzero(ping <= k)) @ a[k].T for k in range(survey.n_pings)])
    got_smoother = posterior_crb(survey, seabed, model)
    got_filter = posterior_crb(survey, seabed, model, kind="filter")
    for got, want in ((got_smoother.position_cov, smoother), (got_filter.position_cov, filt)):
        scale = np.abs(want).max(axis=(1, 2), keepdims=True)
        assert np.all(np.abs(got - want) <= 1e-8 * scale)
    np.testing.assert_allclose(got_smoother.calibration_cov, full[2:4, 2:4], rtol=1e-8)
    assert got_smoother.tide_std == pytest.approx(np.sqrt(full[4, 4]), rel=1e-8)
    old = posterior_crb(survey, seabed, MODEL)  # and the field does matter here
    assert bound_rmse(got_smoother) > 1.02 * bound_rmse(old)


@pytest.mark.parametrize("kind", ["smoother", "filter"])
def test_the_map_error_never_lowers_the_bound(kind):
    survey, seabed = _survey(), _seabed()
    without = posterior_crb(survey, seabed, MODEL, kind=kind)
    for length in (10.0, 60.0, 400.0):
        with_field = posterior_crb(survey, seabed, FIELD.replace(map_correlation_length=length), kind=kind)
        gap = np.linalg.eigvalsh(with_field.position_cov - without.position_cov)
        assert np.all(gap >= -1e-9 * np.abs(without.position_cov).max())
        assert bound_rmse(with_field) > bound_rmse(without)


def test_the_change_since_the_map_is_a_field_of_the_bound():
    """A stated change adds a field of its own: the bound on the map's error and the change
    exceeds the bound on the map's error alone, and equals the bound on a map that states both
    as one field of the same std and range (the change's fields add up like the map's own)."""
    survey, seabed = _survey(), _seabed()
    model = FIELD.replace(map_correlation_length=60.0)
    alone = posterior_crb(survey, seabed, model)
    changed = posterior_crb(survey, seabed, model.replace(map_change_std=0.3, map_change_length=60.0))
    assert bound_rmse(changed) > bound_rmse(alone)
    assert changed.field_nodes == pytest.approx(2 * alone.field_nodes, rel=0.01)
    std = float(np.hypot(FIELD.map_std, 0.3))
    one = posterior_crb(survey, seabed, model.replace(map_std=std))
    assert bound_rmse(changed) == pytest.approx(bound_rmse(one), rel=1e-3)


def _two_passes(passes: int) -> Survey:
    """North along a line at 2 m/s, one ping a second (``passes=2``: then back south on it)."""
    t = np.arange(200.0 * passes)
    north = np.where(t < 200, 200 + 2 * t, 200 + 2 * (399 - t))
    psi = np.where(t < 200, 0.0, np.pi)
    truth = np.column_stack([north, 500 + 0 * t, psi])
    offset = np.tile(np.linspace(-20.0, 20.0, 9), (t.size, 1))
    return Survey(time=t, dr_pose=truth, vehicle_depth=0 * t, beam_forward=0 * offset,
                  beam_starboard=offset, beam_depth=25 + 0 * offset, true_pose=truth)


def test_a_long_range_map_error_is_shared_by_a_second_pass_of_the_same_line():
    # A plane sloping north, the tide known, a DR so good that a pass is one rigid offset: with
    # independent map errors a second pass over the same footprints halves the north variance;
    # with a map error of long range the second pass meets the same errors and gains nothing, and
    # the north error cannot drop below what a constant map error hides, about (s / slope)^2.
    axis = np.arange(0.0, 1001.0, 10.0)
    seabed = BathymetryMap(north=axis, east=axis, depth=20 + 0.04 * axis[:, None] + 0 * axis)
    model = NavigationModel(speed_noise=1e-4, heading_noise=0.0, heading_walk=0.0, speed_scale_std=1e-6,
                            heading_bias_std=1e-6, initial_position_std=10.0, sounding_std=0.2,
                            tide_std=0.0, map_std=0.3, map_correlation_length=2000.0)
    white = model.replace(sounding_std=float(np.hypot(0.2, 0.3)), map_std=0.0)
    north = {}
    for name, m in (("shared", model), ("independent", white)):
        one, two = (posterior_crb(_two_passes(p), seabed, m).position_cov[:200, 0, 0] for p in (1, 2))
        north[name] = (one, two)
    one, two = north["independent"]
    assert np.mean(two / one) == pytest.approx(0.5, abs=0.02)
    one, two = north["shared"]
    assert np.mean(two / one) > 0.95
    assert np.min(two) > 0.5 / (1 / 10.0**2 + (0.04 / 0.3) ** 2)  # half the constant error's floor
    assert np.min(two) > 100 * np.max(north["independent"][1])


@pytest.mark.parametrize("exact_pings", [250, 12])
def test_the_filter_bound_is_never_below_the_smoother_bound(monkeypatch, exact_pings):
    # 300 pings on circles (the track turns all the time) over the plane: the survey revisits its
    # own footprints. With 12 exact pings the rest are interpolated.
    monkeypatch.setattr(field_bound, "FILTER_PINGS", exact_pings)
    survey, seabed = _survey(300, 7), _seabed(east_end=1000.0)
    model = FIELD.replace(map_correlation_length=40.0)
    smooth = posterior_crb(survey, seabed, model)
    filt = posterior_crb(survey, seabed, model, kind="filter")
    gap = np.linalg.eigvalsh(filt.position_cov - smooth.position_cov)
    assert np.all(gap >= -1e-9 * np.abs(smooth.position_cov).max())
    assert np.max(gap[:-5]) > 1e-2
    np.testing.assert_allclose(filt.position_cov[-1], smooth.position_cov[-1], rtol=1e-8)
    if exact_pings == 12:  # where solved, the same as solving at every ping
        monkeypatch.setattr(field_bound, "FILTER_PINGS", survey.n_pings)
        every = posterior_crb(survey, seabed, model, kind="filter").position_cov
        pings = np.unique(np.round(np.linspace(0, survey.n_pings - 1, 12)).astype(int))
        np.testing.assert_allclose(filt.position_cov[pings], every[pings], rtol=1e-8,
                                   atol=1e-10 * np.abs(every).max())


@pytest.mark.parametrize("kind", ["smoother", "filter"])
def test_the_maps_offset_is_an_unknown_the_slope_shows_as_the_vehicles_position(kind):
    # On a plane a rigid offset o of the map is seen exactly as the vehicle's position is
    # (g . o): the bound equals a dense solve with o two more inputs of prior std 1 m, above
    # the bound without it.
    survey, seabed = _survey(), _seabed()
    model = MODEL.replace(map_offset_std=1.0)
    a, e, tide_row, var = _design(survey, model)
    used, turn = _soundings(survey, seabed)
    ping, _ = np.nonzero(used)
    h = -(np.array(SLOPE) @ a)[ping] - turn[used][:, None] * e[ping] + tide_row
    h = np.column_stack([h, np.tile(-np.array(SLOPE), (h.shape[0], 1))])
    var = np.r_[var, 1.0, 1.0]
    a = np.concatenate([a, a[:, :, :2]], axis=2)  # the vehicle's position, the offset apart
    a[:, :, -2:] = 0.0
    keep = var > 0
    a, h, var = a[:, :, keep], h[:, keep], var[keep]

    def covariance(rows):
        return np.linalg.inv(np.diag(1 / var) + h[rows].T @ h[rows] / model.sounding_std**2)

    if kind == "smoother":
        want = np.einsum("kap,pq,kbq->kab", a, covariance(np.arange(h.shape[0])), a)
    else:
        want = np.array([a[k] @ covariance(np.flatnonzero(ping <= k)) @ a[k].T
                         for k in range(survey.n_pings)])
    got = posterior_crb(survey, seabed, model, kind=kind).position_cov
    scale = np.abs(want).max(axis=(1, 2), keepdims=True)
    assert np.all(np.abs(got - want) <= 1e-8 * scale)
    assert bound_rmse(posterior_crb(survey, seabed, MODEL, kind=kind)) < np.sqrt(
        np.mean(np.trace(got, axis1=1, axis2=2)))
