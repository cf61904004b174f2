"""Tests of the posterior Cramér-Rao bound with the map's error as a Gaussian-Markov field: without a
map error it is the bound it always was (numbers pinned before the field came in); a vanishing field
tends to it; on a planar seabed it equals a dense linear-Gaussian solve with the field's covariance
among all soundings; the field never lowers the bound, and a long-range field shared by two passes
of one line keeps the second pass from halving the first's variance; the filter bound is never below
the smoother's."""

from __future__ import annotations

import numpy as np
import pytest

import tangraph.eval.map_field as map_field
from tangraph.eval import bound_rmse, posterior_crb
from tangraph.eval.map_field import map_error_field
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel, map_error
from tangraph.survey import Survey
from tests.eval.test_crb import MODEL, SLOPE, _jd, _seabed, _soundings, _survey

FIELD = MODEL.replace(map_std=0.3, map_correlation_length=60.0)


def _doctest_case():
    """The sloped seabed of ``posterior_crb``'s example: north-going, the tide known."""
    axis = np.arange(0.0, 1001.0, 10.0)
    seabed = BathymetryMap(north=axis, east=axis, depth=20 + 0.05 * axis[:, None] + 0 * axis)
    t = np.arange(100.0)
    truth = np.column_stack([100 + 2 * t, 500 + 0 * t, 0 * t])
    offset = np.tile(np.linspace(-20.0, 20.0, 9), (100, 1))
    survey = Survey(time=t, dr_pose=truth, vehicle_depth=0 * t, beam_forward=0 * offset,
                    beam_starboard=offset, beam_depth=25 + 0 * offset, true_pose=truth)
    return survey, seabed, NavigationModel(tide_std=0.0)


# The bound at pings 0, 5, 17 and the last (row-major 2 x 2), the calibration covariance and the tide
# std, computed at 95ab902, before the map error field (repr of the float64 values).
PINNED = {
    ("doctest", "filter"): (
        [[9.999999999999986, 0.0, 0.0, 100.0],
         [1.8324112892794624, -6.6503970716460796e-18, -6.6503970716460796e-18, 100.12230545260074],
         [0.7352120222501969, -1.9130934999017277e-17, -1.9130934999017277e-17, 101.1023682657522],
         [0.44197177504418667, -5.27188708468719e-17, -5.27188708468719e-17, 117.14066722628775]],
        [3.694324168799874e-05, -8.202096674023627e-24, -8.202096674023627e-24, 0.0004309041737141203], 0.0),
    ("doctest", "smoother"): (
        [[0.4403507598793807, 2.211447468192402e-32, 2.211447468192402e-32, 100.00000000000016],
         [0.3725927920157442, -2.6471852524526444e-18, -2.6471852524526444e-18, 100.0555904173715],
         [0.2513699096391293, -9.008719100532431e-18, -9.008719100532431e-18, 100.54062522481355],
         [0.44197177504418667, -5.27188708468719e-17, -5.27188708468719e-17, 117.14066722628775]],
        [3.694324168799874e-05, -8.202096674023627e-24, -8.202096674023627e-24, 0.0004309041737141203], 0.0),
    ("turning", "filter"): (
        [[21.94656488549594, 2.2900763358762553, 2.2900763358762553, 23.282442748081827],
         [22.23457255664754, 2.335617458637607, 2.3356174586376075, 23.722694680194685],
         [23.73128154556751, 2.8200622652918574, 2.8200622652918574, 25.384304040322476],
         [25.644345868143713, 4.441856303577177, 4.441856303577177, 28.35212887169172]],
        [0.0002700358564555495, -4.3928562154407765e-05, -4.3928562154407765e-05, 0.0002826543615527324],
        0.22659938267667737),
    ("turning", "smoother"): (
        [[21.821556483586342, 2.3838326372218033, 2.3838326372218033, 23.21212552195444],
         [22.08478574754946, 2.4634891921000266, 2.4634891921000266, 23.469521446304643],
         [23.265771430552217, 3.002552097826587, 3.002552097826587, 24.51604701939478],
         [25.644345868143713, 4.441856303577177, 4.441856303577177, 28.35212887169172]],
        [0.0002700358564555495, -4.3928562154407765e-05, -4.3928562154407765e-05, 0.0002826543615527324],
        0.22659938267667737),
}


@pytest.mark.parametrize(("case", "kind"), list(PINNED))
def test_without_a_map_error_the_bound_is_the_one_before_the_field(case, kind):
    survey, seabed, model = _doctest_case() if case == "doctest" else (_survey(), _seabed(), MODEL)
    assert map_error(seabed, model).is_zero
    got = posterior_crb(survey, seabed, model, kind=kind)
    position, calibration, tide = PINNED[(case, kind)]
    pings = [0, 5, 17, survey.n_pings - 1]
    want = np.array(position).reshape(-1, 2, 2)
    np.testing.assert_allclose(got.position_cov[pings], want, rtol=1e-12, atol=1e-12 * np.abs(want).max())
    np.testing.assert_allclose(got.calibration_cov.ravel(), calibration, rtol=1e-12, atol=1e-15)
    assert got.tide_std == pytest.approx(tide, rel=1e-12)
    assert not got.map_error and got.field_nodes == 0


def test_a_map_that_says_it_is_exact_overrides_the_models_default():
    survey, seabed = _survey(), _seabed()
    exact = seabed.replace(depth_std=np.zeros(seabed.shape))
    got = posterior_crb(survey, exact, MODEL.replace(map_std=0.3))
    want = posterior_crb(survey, seabed, MODEL)
    assert not got.map_error
    np.testing.assert_array_equal(got.position_cov, want.position_cov)


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
    # map_field.ZERO_VARIANCE in natural units, about that much times the pings off, relatively.
    model = MODEL.replace(heading_noise=0.0, heading_walk=0.0, speed_noise=0.0)
    survey, seabed = _survey(), _seabed()
    old = posterior_crb(survey, seabed, model)
    got = posterior_crb(survey, seabed, model.replace(map_std=3e-7, map_correlation_length=60.0))
    np.testing.assert_allclose(got.position_cov, old.position_cov, rtol=1e-5)


def _design(survey: Survey, model: NavigationModel):
    """The dense linear model of the DR errors over its independent inputs (as in test_crb's batch
    reference): ping k's error is ``a[k] @ theta``, its heading error ``e[k] @ theta``; with the
    tide's row and the inputs' prior variances."""
    t, truth = survey.time, survey.true_pose
    k = t.size
    d, dt = np.diff(truth[:, :2], axis=0), np.diff(t)
    var = [model.initial_position_std**2] * 2 + list(model.calibration_std**2) + [model.tide_std**2]
    var += list(np.column_stack([(model.speed_noise * dt) ** 2] * 2 + [model.heading_walk**2 * dt]).ravel())
    var += [model.heading_noise**2] * k
    eye = np.eye(len(var))
    white = 5 + 3 * (k - 1)
    dp, walk = eye[:2].copy(), np.zeros(len(var))
    a, e = [dp], [eye[3] + eye[white]]
    for m in range(k - 1):
        dp = dp + np.outer(d[m], eye[2]) + np.outer(_jd(d[m:m + 1])[0], e[-1]) + eye[5 + 3 * m:7 + 3 * m]
        walk = walk + eye[7 + 3 * m]
        a.append(dp)
        e.append(eye[3] + walk + eye[white + m + 1])
    return np.array(a), np.array(e), eye[4], np.array(var)


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
    field = map_error_field(north[used], east[used], map_error(seabed, model))
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
    monkeypatch.setattr(map_field, "FILTER_PINGS", exact_pings)
    survey, seabed = _survey(300, 7), _seabed(east_end=1000.0)
    model = FIELD.replace(map_correlation_length=40.0)
    smooth = posterior_crb(survey, seabed, model)
    filt = posterior_crb(survey, seabed, model, kind="filter")
    gap = np.linalg.eigvalsh(filt.position_cov - smooth.position_cov)
    assert np.all(gap >= -1e-9 * np.abs(smooth.position_cov).max())
    assert np.max(gap[:-5]) > 1e-2
    np.testing.assert_allclose(filt.position_cov[-1], smooth.position_cov[-1], rtol=1e-8)
    if exact_pings == 12:  # where solved, the same as solving at every ping
        monkeypatch.setattr(map_field, "FILTER_PINGS", survey.n_pings)
        every = posterior_crb(survey, seabed, model, kind="filter").position_cov
        pings = np.unique(np.round(np.linspace(0, survey.n_pings - 1, 12)).astype(int))
        np.testing.assert_allclose(filt.position_cov[pings], every[pings], rtol=1e-8,
                                   atol=1e-10 * np.abs(every).max())
