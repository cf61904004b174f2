"""Tests of the posterior Cramér-Rao bound (tangraph.eval.crb): against an independent dense batch
solve and a hand-built scalar Kalman filter on a planar seabed, the pure DR covariance on a flat
one, the order filter >= smoother, monotonicity in the soundings, bad inputs, and (slow) a Monte
Carlo run of an exact estimator on the simulator's own dead reckoning; without a map error it is
the bound it always was (numbers pinned before the map error field came in), also on a map that
says it is exact. The bound's joint solve with the field is tested in test_map_field.py."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.eval import CramerRaoBound, bound_rmse, posterior_crb
from tangraph.maps import BathymetryMap
from tangraph.sensors import (
    KNOWN_STD,
    DeadReckoningModel,
    NavigationModel,
    increment_covariance,
    map_error,
    simulate_dead_reckoning,
)
from tangraph.sensors.dead_reckoning import walk_variance
from tangraph.survey import Survey
from tests.eval.crb_cases import MODEL, SLOPE, _design, _jd, _seabed, _soundings, _survey


def _batch_reference(survey: Survey, seabed: BathymetryMap, model: NavigationModel):
    """Filter and smoother position covariances from a dense batch over the independent inputs.

    The parameters are the start error, the calibration, the tide and every white input (speed
    noise, walk steps, white heading errors); each ping's error is a linear map ``A_k`` of them,
    each sounding a row of the measurement matrix. Covariance = ``A_k (prior^-1 + H^T H / s^2)^-1
    A_k^T`` with the soundings of all pings (smoother) or of pings up to k (filter).
    """
    t, truth = survey.time, survey.true_pose
    k = t.size
    d = np.diff(truth[:, :2], axis=0)
    dt = np.diff(t)
    names, var = [], []

    def add(name, v):
        if v > 0:
            names.append(name)
            var.append(v)

    add("dp_n", model.initial_position_std**2)
    add("dp_e", model.initial_position_std**2)
    add("s", model.speed_scale_std**2)
    add("b", model.heading_bias_std**2)
    add("tide", model.tide_std**2)
    for m in range(k - 1):
        add(("v_n", m), (model.speed_noise * dt[m]) ** 2)
        add(("v_e", m), (model.speed_noise * dt[m]) ** 2)
        add(("u", m), float(walk_variance(model.heading_walk, model.heading_turn_std, dt[m],
                                          np.angle(np.exp(1j * (truth[m + 1, 2] - truth[m, 2]))))))
    for m in range(k):
        add(("n", m), model.heading_noise**2)
    drift = model.tide_drift_std or 0.0
    keep = np.exp(-dt / model.tide_drift_time) if drift > 0 else np.zeros(k - 1)
    for m in range(k):  # the tide's drift: x_0 and the innovations of x_m
        add(("x", m), drift**2 * (1.0 if m == 0 else 1.0 - keep[m - 1] ** 2))
    col = {name: i for i, name in enumerate(names)}
    n_par = len(names)

    def unit(name):
        row = np.zeros(n_par)
        if name in col:
            row[col[name]] = 1.0
        return row

    heading = unit("b")  # e_0 = b + n_0 (w_0 = 0)
    dp = np.stack([unit("dp_n"), unit("dp_e")])
    a, e = [dp], [heading + unit(("n", 0))]
    walk = np.zeros(n_par)
    for m in range(k - 1):
        e_m = heading + walk + unit(("n", m))
        dp = dp + np.outer(d[m], unit("s")) + np.outer(_jd(d[m:m + 1])[0], e_m)
        dp = dp + np.stack([unit(("v_n", m)), unit(("v_e", m))])
        walk = walk + unit(("u", m))
        a.append(dp)
        e.append(heading + walk + unit(("n", m + 1)))
    drift = [unit(("x", 0))]
    for m in range(k - 1):
        drift.append(keep[m] * drift[-1] + unit(("x", m + 1)))
    used, turn = _soundings(survey, seabed)
    g = np.array(SLOPE)
    prior = np.diag(1.0 / np.array(var))
    info_by_ping = []
    for i in range(k):
        rows = [-(g @ a[i]) - turn[i, j] * e[i] + unit("tide") + drift[i]
                for j in np.flatnonzero(used[i])]
        h = np.array(rows).reshape(-1, n_par)
        info_by_ping.append(h.T @ h / model.measurement_std**2)
    total = prior + sum(info_by_ping)
    full = np.linalg.inv(total)
    smoother = np.array([ai @ full @ ai.T for ai in a])
    running = prior.copy()
    filt = []
    for i in range(k):
        running = running + info_by_ping[i]
        filt.append(a[i] @ np.linalg.inv(running) @ a[i].T)
    return np.array(filt), smoother


def _close(got, want, rtol=1e-8):
    scale = np.max(np.abs(want), axis=(-2, -1), keepdims=True)
    assert np.all(np.abs(got - want) <= rtol * scale)


@pytest.mark.parametrize("model", [MODEL, MODEL.replace(heading_noise=0.0, heading_walk=0.0, speed_noise=0.0),
                                   MODEL.replace(tide_std=0.0), MODEL.replace(heading_turn_std=0.05),
                                   MODEL.replace(heading_walk=0.0, heading_turn_std=0.05),
                                   MODEL.replace(tide_drift_std=0.3, tide_drift_time=20.0),
                                   MODEL.replace(tide_std=0.0, tide_drift_std=0.3, tide_drift_time=20.0)],
                         ids=["all-noises", "no-white", "tide-known", "turning-walk", "turn-walk-only",
                              "tide-drift", "drift-only"])
def test_bound_equals_a_dense_batch_solve_on_a_planar_seabed(model):
    survey, seabed = _survey(), _seabed()
    used, _ = _soundings(survey, seabed)
    assert 0 < used.sum() < np.isfinite(survey.beam_depth).sum()  # some footprints fall off the map
    filt, smooth = _batch_reference(survey, seabed, model)
    got_filter = posterior_crb(survey, seabed, model, kind="filter")
    got_smoother = posterior_crb(survey, seabed, model)
    assert got_filter.kind == "filter" and got_smoother.kind == "smoother"
    assert got_smoother.n_soundings == used.sum()
    _close(got_filter.position_cov, filt)
    _close(got_smoother.position_cov, smooth)


@pytest.mark.parametrize("known", [False, True], ids=["calibration-uncertain", "calibration-known"])
def test_filter_bound_equals_a_hand_built_scalar_kalman_filter(known):
    # State (dp_n, dp_e, s, b, tide); one scalar update per sounding in the covariance form. A
    # known calibration (prior std 0) is held at KNOWN_STD, as the graph holds it.
    model = MODEL.replace(heading_noise=0.0, heading_walk=0.0)
    if known:
        model = model.replace(speed_scale_std=0.0, heading_bias_std=0.0)
    survey, seabed = _survey(), _seabed()
    used, turn = _soundings(survey, seabed)
    d = np.diff(survey.true_pose[:, :2], axis=0)
    dt = np.diff(survey.time)
    calibration = np.maximum(model.calibration_std, KNOWN_STD) ** 2
    p = np.diag([25.0, 25.0, *calibration, model.tide_std**2])
    want = []
    for i in range(survey.n_pings):
        if i:
            f = np.eye(5)
            f[:2, 2] = d[i - 1]
            f[:2, 3] = [-d[i - 1, 1], d[i - 1, 0]]
            p = f @ p @ f.T + np.diag([(model.speed_noise * dt[i - 1]) ** 2] * 2 + [0, 0, 0])
        for j in np.flatnonzero(used[i]):
            h = np.array([-SLOPE[0], -SLOPE[1], 0.0, -turn[i, j], 1.0])
            ph = p @ h
            p = p - np.outer(ph, ph) / (h @ ph + model.measurement_std**2)
        want.append(p)
    want = np.array(want)
    got = posterior_crb(survey, seabed, model, kind="filter")
    _close(got.position_cov, want[:, :2, :2])
    _close(got.calibration_cov, want[-1, 2:4, 2:4])
    assert got.tide_std == pytest.approx(np.sqrt(want[-1, 4, 4]), rel=1e-8)


@pytest.mark.parametrize("map_std", [0.0, 0.2])
def test_a_known_calibration_gives_a_finite_bound_below_the_uncertain_one(map_std):
    """Both bounds of a model that knows its DR's constant errors (stds 0), with a perfect map
    and with a map error field: finite, no larger than with the errors uncertain, and the
    calibration known."""
    survey, seabed = _survey(), _seabed()
    uncertain = MODEL.replace(map_std=map_std, map_correlation_length=10.0)
    known = uncertain.replace(speed_scale_std=0.0, heading_bias_std=0.0)
    for kind in ("filter", "smoother"):
        a = posterior_crb(survey, seabed, known, kind=kind)
        b = posterior_crb(survey, seabed, uncertain, kind=kind)
        assert np.all(np.isfinite(a.position_cov)) and bound_rmse(a) <= bound_rmse(b) * (1 + 1e-9)
        assert np.all(np.abs(a.calibration_cov) <= KNOWN_STD**2 * (1 + 1e-6))


def test_filter_bound_is_above_the_smoother_bound_and_equal_at_the_last_ping():
    survey, seabed = _survey(60, 9), _seabed()
    filt = posterior_crb(survey, seabed, MODEL, kind="filter")
    smooth = posterior_crb(survey, seabed, MODEL, kind="smoother")
    gap = np.linalg.eigvalsh(filt.position_cov - smooth.position_cov)
    assert np.all(gap >= -1e-9 * np.abs(filt.position_cov).max())
    assert np.max(gap[:-5]) > 1e-3  # the smoother does gain on earlier pings
    _close(filt.position_cov[-1], smooth.position_cov[-1], rtol=1e-9)
    _close(filt.calibration_cov, smooth.calibration_cov, rtol=1e-9)
    assert filt.tide_std == pytest.approx(smooth.tide_std, rel=1e-9)
    assert bound_rmse(filt) > bound_rmse(smooth)


@pytest.mark.parametrize("kind", ["filter", "smoother"])
def test_on_a_flat_seabed_the_bound_is_the_dead_reckoning_covariance(kind):
    # No gradient, no position information: the start prior, the white DR errors (as the sensors'
    # increment covariance has them) and the calibration priors propagated along the track.
    model = MODEL.replace(heading_noise=0.0)
    survey, seabed = _survey(), _seabed(slope=(0.0, 0.0))
    got = posterior_crb(survey, seabed, model, kind=kind)
    t, truth = survey.time, survey.true_pose
    white = increment_covariance(model.dead_reckoning, t, truth, 0, np.arange(t.size))[:, :2, :2]
    c, s = np.cos(truth[0, 2]), np.sin(truth[0, 2])
    r0 = np.array([[c, -s], [s, c]])
    chord = truth[:, :2] - truth[0, :2]
    across = _jd(chord)
    want = (model.initial_position_std**2 * np.eye(2) + r0 @ white @ r0.T
            + model.speed_scale_std**2 * chord[:, :, None] * chord[:, None, :]
            + model.heading_bias_std**2 * across[:, :, None] * across[:, None, :])
    _close(got.position_cov, want, rtol=1e-10)
    _close(got.calibration_cov, np.diag(model.calibration_std**2), rtol=1e-12)
    assert got.tide_std < model.tide_std  # the tide alone is measured


def test_more_soundings_and_less_noise_give_a_smaller_bound():
    seabed = _seabed()
    base = posterior_crb(_survey(beams=5), seabed, MODEL)
    more = posterior_crb(_survey(beams=15), seabed, MODEL)
    quieter = posterior_crb(_survey(beams=5), seabed, MODEL.replace(sounding_std=0.1))
    for better in (more, quieter):
        gap = np.linalg.eigvalsh(base.position_cov - better.position_cov)
        assert np.all(gap >= -1e-9 * base.position_cov.max())
        assert bound_rmse(better) < bound_rmse(base)
    assert more.n_soundings > base.n_soundings


def test_bad_inputs_name_the_problem():
    survey, seabed = _survey(), _seabed()
    with pytest.raises(TangraphError, match="no true_pose"):
        posterior_crb(survey.replace(true_pose=None), seabed, MODEL)
    with pytest.raises(TangraphError, match="model must be a NavigationModel"):
        posterior_crb(survey, seabed, DeadReckoningModel())
    with pytest.raises(TangraphError, match="bathymetry must be a BathymetryMap"):
        posterior_crb(survey, seabed.depth, MODEL)
    with pytest.raises(TangraphError, match="survey must be a Survey"):
        posterior_crb(survey.true_pose, seabed, MODEL)
    with pytest.raises(TangraphError, match="kind must be one of"):
        posterior_crb(survey, seabed, MODEL, kind="ekf")
    with pytest.raises(TangraphError, match="position_cov must be"):
        CramerRaoBound(np.zeros((3, 2)), np.eye(2), 0.0, "filter")


@pytest.mark.slow
def test_an_exact_estimator_of_the_simulated_dead_reckoning_meets_the_bound():
    # The simulator's DR (drawn calibration, walk, white errors, start offset) over a planar seabed,
    # soundings of the true footprints plus tide and noise. The estimator knows only the DR and the
    # soundings: the exact batch (Gauss-Newton, one step from zero) of the linearised model, with
    # its geometry taken from the DR. If the model's signs and terms match the simulator, the
    # final-ping NEES against the smoother bound averages 2 (chi-square(2)) over the runs and the
    # mean squared error equals the bound's trace. The wide swath makes the heading terms of the
    # soundings count: a wrong sign of J in either the steps or the soundings raises the mean
    # squared error by 20-30 % (measured), six standard errors at 1000 runs.
    runs = 1000
    model = MODEL.replace(sounding_std=0.2)
    seabed = _seabed(east_end=1000.0)
    template = _survey(30, 11, width=100.0)
    bound = posterior_crb(template, seabed, model)
    t, truth = template.time, template.true_pose
    g = np.array(SLOPE)
    rng = np.random.default_rng(11)
    nees, sq = [], []
    for _ in range(runs):
        scale, bias = rng.normal(0.0, model.calibration_std)
        dr_model = DeadReckoningModel(heading_bias=bias, speed_scale=scale, speed_noise=model.speed_noise,
                                      heading_walk=model.heading_walk, heading_noise=model.heading_noise)
        start = truth[0] + np.r_[rng.normal(0.0, model.initial_position_std, 2), 0.0]
        dr = simulate_dead_reckoning(t, truth, dr_model, rng=rng, start_pose=start).pose
        tide = rng.normal(0.0, model.tide_std)
        survey = template.replace(dr_pose=dr)
        n_true, e_true = survey.footprints(truth)
        z = seabed.depth_at(n_true, e_true) + tide + model.measurement_std * rng.normal(size=n_true.shape)
        survey = survey.replace(beam_depth=np.where(np.isfinite(template.beam_depth), z, np.nan))
        n_dr, e_dr = survey.footprints(dr)
        residual = z - seabed.depth_at(n_dr, e_dr)  # measured - map, laid from the DR
        # The estimator's linear model, built on the DR geometry (the truth stays unknown).
        est = survey.replace(true_pose=dr)
        a, e, tide_row, var = _design(est, model)
        turn = g[1] * (n_dr - dr[:, :1]) - g[0] * (e_dr - dr[:, 1:2])
        used = np.isfinite(residual) & np.isfinite(template.beam_depth)
        ping = np.nonzero(used)[0]
        h = -(g @ a)[ping] - turn[used][:, None] * e[ping] + tide_row
        r = residual[used]
        info = np.diag(1.0 / var) + h.T @ h / model.measurement_std**2
        theta = np.linalg.solve(info, h.T @ r / model.measurement_std**2)
        error = a[-1] @ theta - (dr[-1, :2] - truth[-1, :2])  # estimated minus true DR error
        nees.append(error @ np.linalg.solve(bound.position_cov[-1], error))
        sq.append(error @ error)
    assert abs(np.mean(nees) - 2.0) < 3.5 * 2.0 / np.sqrt(runs)  # a mean of chi-square(2)
    ratio = np.mean(sq) / np.trace(bound.position_cov[-1])
    assert abs(ratio - 1.0) < 3.5 * np.std(sq) / np.sqrt(runs) / np.trace(bound.position_cov[-1])


# -- without a map error -----------------------------------------------------------------------
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
def test_the_field_bound_carries_the_tides_drift_as_the_plain_one_does(kind):
    # a map error too small to matter: the field's solve with the drift per ping equals the
    # Kalman/RTS bound (itself equal to the dense batch solve above), above the constant tide's
    survey, seabed = _survey(), _seabed()
    drifting = MODEL.replace(tide_drift_std=0.3, tide_drift_time=20.0)
    plain = posterior_crb(survey, seabed, drifting, kind=kind)
    tiny = drifting.replace(map_std=1e-4, map_correlation_length=30.0)
    field = posterior_crb(survey, seabed, tiny, kind=kind)
    assert field.map_error and not plain.map_error
    np.testing.assert_allclose(field.position_cov, plain.position_cov, rtol=0,
                               atol=1e-6 * plain.position_cov.max())
    constant = posterior_crb(survey, seabed, MODEL, kind=kind)
    assert np.all(np.trace(plain.position_cov, axis1=1, axis2=2)
                  >= np.trace(constant.position_cov, axis1=1, axis2=2) - 1e-9)
