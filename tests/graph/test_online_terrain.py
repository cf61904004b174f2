"""Every sounding in the online graph once it tracks (tangraph.graph.online_terrain): the factor's
Jacobians, no sounding counted twice, accuracy against the windows' fixes, a flat map, faulty
pings, and the settings it refuses."""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.fix_records import FixStatus
from tangraph.graph import GraphConfig, GraphNavigator, navigate_online, smooth_survey
from tangraph.graph.calibration import CALIBRATION
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel
from tests.graph.track_errors import rmse

SOUNDINGS = GraphConfig().replace(terrain="soundings")


@pytest.fixture(scope="module")
def tracked(small_survey, rough_map):
    return GraphNavigator(small_survey, rough_map, SOUNDINGS).run()


def test_the_tracking_factors_are_linear_on_the_key_and_calibration(tracked):
    """Each tracking factor is the soundings' information linearised at the mode of the key's
    belief given them (:func:`tangraph.graph.terrain_factors.chain_information`, tested against
    the dense covariance there): a linear factor on its key pose and the calibration, positive
    semi-definite, informative in position, the same wherever iSAM2 relinearises it."""
    graph = tracked.isam.getFactorsUnsafe()
    factors = [graph.at(i) for i in range(graph.size())]
    factors = [f for f in factors if isinstance(f, gtsam.LinearContainerFactor)]
    assert len(factors) > 3, "no terrain factor in iSAM2's window"
    values = tracked.isam.calculateEstimate()
    for factor in factors:
        keys = list(factor.keys())
        assert CALIBRATION in keys and keys[0] != CALIBRATION
        linear = factor.factor()  # the soundings' information where they were judged
        hessian = linear.augmentedInformation()[:-1, :-1]
        eigen = np.linalg.eigvalsh(hessian)
        assert eigen.min() > -1e-9 * eigen.max()
        assert np.linalg.eigvalsh(hessian[:2, :2]).min() > 0  # the key's position is told
        # relinearised anywhere, the same information (a linear factor)
        np.testing.assert_allclose(factor.linearize(values).augmentedInformation()[:-1, :-1], hessian,
                                   rtol=1e-9, atol=1e-9 * eigen.max())


def test_tracking_counts_no_sounding_twice_and_beats_the_fixes(tracked, small_survey, rough_map):
    nav = tracked
    terrain = nav.terrain
    assert terrain is not None and terrain.factors > 10 and terrain.episodes
    track = nav.track()
    assert track.meta["terrain"]["pings"] > 0.5 * small_survey.n_pings
    # every window the policy took lies before the pings the factors hold began; those made while
    # tracking are checks, not used
    first_tracked = terrain.episodes[0][0]
    checks = [r for r in track.fixes if r.status == FixStatus.CHECKED]
    assert len(checks) > 10 and not any(r.accepted for r in checks)
    for record in track.fixes:
        if record.index > first_tracked:
            assert record.status == FixStatus.CHECKED
    fixes = navigate_online(small_survey, rough_map, GraphConfig())
    half = small_survey.n_pings // 2
    later = slice(half, None)
    err = np.hypot(*(track.pose[later, :2] - small_survey.true_pose[later, :2]).T)
    err_fixes = np.hypot(*(fixes.pose[later, :2] - small_survey.true_pose[later, :2]).T)
    # measured: 0.45 against 0.72 m over the second half
    assert np.sqrt(np.mean(err**2)) < 0.8 * np.sqrt(np.mean(err_fixes**2))
    assert "tide" in track.meta and track.meta["tide"]["tide_std"] < 0.1


def test_on_a_flat_map_it_never_tracks(small_survey, rough_map):
    flat = BathymetryMap(rough_map.north, rough_map.east, np.full(rough_map.shape, float(np.nanmedian(
        rough_map.depth))))
    track = navigate_online(small_survey, flat, SOUNDINGS)
    plain = navigate_online(small_survey, flat, GraphConfig())
    assert track.meta["terrain"]["factors"] == 0
    np.testing.assert_allclose(track.pose, plain.pose, atol=1e-6)


def test_a_block_of_biased_pings_is_left_out(small_survey, rough_map, tracked):
    biased = small_survey.beam_depth.copy()
    block = slice(120, 135)
    biased[block] += 5.0
    survey = dataclasses.replace(small_survey, beam_depth=biased)
    model = NavigationModel.from_survey(small_survey)
    track = navigate_online(survey, rough_map, SOUNDINGS, model=model)
    clean = tracked.track()
    assert track.meta["terrain"]["pings"] <= clean.meta["terrain"]["pings"] - 10
    assert rmse(track, survey.true_pose) < 1.5 * rmse(clean, small_survey.true_pose)  # measured: 1.0 x


def test_the_smoother_weighs_fixes_and_the_point_mass_front_end_is_refused(small_survey, rough_map):
    with pytest.raises(TangraphError, match="terrain = 'soundings'"):
        GraphConfig().replace(front_end="pmf", terrain="soundings")
    with pytest.raises(TangraphError, match="terrain must be one of"):
        GraphConfig().replace(terrain="pings")
    a = smooth_survey(small_survey, rough_map, SOUNDINGS)
    b = smooth_survey(small_survey, rough_map, GraphConfig())
    np.testing.assert_array_equal(a.pose, b.pose)


def test_windows_may_overlap_each_other_but_not_the_tracked_pings():
    from types import SimpleNamespace

    from tangraph.graph.online_terrain import OnlineTerrain

    nav = SimpleNamespace(window_first={19: 0, 29: 10, 39: 20, 49: 30})
    terrain = OnlineTerrain(np.zeros((50, 1)))
    terrain.window_taken(19)
    assert terrain.window_allowed(nav, 29)  # TAP's windows overlap by design
    assert terrain.free_ping == 20  # a factor starts after the windows' pings
    terrain.next_ping = terrain.free_ping = 35  # a factor held the pings up to 34
    assert not terrain.window_allowed(nav, 39)
    assert not terrain.window_allowed(nav, 49)  # its first ping, 30, a factor holds
    terrain.next_ping = 30
    assert terrain.window_allowed(nav, 49)
    terrain.tracking = True
    assert not terrain.window_allowed(nav, 49)  # no window while tracking


def _terrain(variance, increment_cov):
    """What :func:`tangraph.graph.online_terrain._information` reads of a ping terrain."""
    from types import SimpleNamespace

    return SimpleNamespace(variance=variance, increment_cov=increment_cov)


def test_the_soundings_innovation_is_the_nis_of_the_shift_they_pull_for():
    from tangraph.graph.online_terrain import _innovation

    rng = np.random.default_rng(3)
    grad = rng.normal(0.0, 0.1, (4, 30, 2))
    terrain = _terrain(np.full((4, 30), 0.2**2), np.zeros((4, 3, 3)))  # no DR noise between the pings
    used, noise = np.ones((4, 30), bool), np.zeros((4, 30, 3))
    shift = np.array([1.5, -0.5])
    residual = grad @ shift  # soundings that fit the map moved by `shift`, no noise
    prior = np.diag([0.5, 0.8]) ** 2
    h = np.einsum("kbi,kbj->ij", grad, grad) / 0.2**2
    expected = shift @ np.linalg.solve(prior + np.linalg.inv(h), shift)
    nis = _innovation(terrain, used, residual, grad, noise, None, prior, 0.0)
    assert nis == pytest.approx(expected, rel=1e-9)
    # a common offset the tide's uncertainty explains costs little; one it does not, a lot
    offset = np.full(residual.shape, 1.0)
    assert _innovation(terrain, used, offset, grad, noise, None, prior, 4.0) < 1.0
    assert _innovation(terrain, used, offset, grad, noise, None, prior, 0.01) > 50.0


def test_the_soundings_innovation_is_chi_square_with_the_noise_their_pings_share():
    """With the DR noise of the pings' increments and the tide's drift since the key (both
    shared by the soundings of a ping), residuals drawn from the model give the innovation's
    chi-square(3) mean (measured 2.96); weighing each sounding with its ping's noise as its own
    and leaving the drift out, as the gate did, gave 4.34, and leaving the drift out alone 4.27."""
    from tangraph.graph.online_terrain import _innovation

    rng = np.random.default_rng(5)
    k, b, var = 6, 40, 0.2**2
    grad = rng.normal(0.0, 0.05, (k, b, 2))
    noise = rng.normal(0.0, 0.05, (k, b, 3))  # d r / d (DR noise of the increment from the key)
    steps = np.stack([np.diag([0.3, 0.3, 1e-4])] * k)
    cumulative = np.cumsum(steps, axis=0)
    drift = 0.02 * np.arange(1, k + 1)  # the tide's drift's variance since the key
    terrain, used = _terrain(np.full((k, b), var), cumulative), np.ones((k, b), bool)
    prior = np.diag([1.0, 0.6]) ** 2
    tide_var = 0.05
    a = -np.concatenate([grad, np.ones((k, b, 1))], axis=-1)
    values, without_drift = [], []
    for _ in range(400):
        theta = np.append(rng.multivariate_normal(np.zeros(2), prior), rng.normal(0.0, np.sqrt(tide_var)))
        u = np.cumsum([rng.multivariate_normal(np.zeros(3), s) for s in steps], axis=0)  # (K, 3)
        d = np.cumsum(rng.normal(0.0, np.sqrt(0.02), k))
        residual = (a @ theta + np.einsum("kbq,kq->kb", noise, u) - d[:, None]
                    + rng.normal(0, np.sqrt(var), (k, b)))
        values.append(_innovation(terrain, used, residual, grad, noise, drift, prior, tide_var))
        without_drift.append(_innovation(terrain, used, residual, grad, noise, None, prior, tide_var))
    # chi-square(3): mean 3, its Monte Carlo std sqrt(6 / 400) = 0.12
    assert abs(np.mean(values) - 3.0) < 4 * np.sqrt(6.0 / 400)
    assert np.mean(without_drift) > 3.0 + 4 * np.sqrt(6.0 / 400)


def test_blocks_of_shifted_footprints_do_not_pull_the_tracking_off(small_survey, rough_map, tracked):
    from tangraph.sim.faults import outlier_blocks

    model = NavigationModel.from_survey(small_survey)
    clean = rmse(tracked.track(), small_survey.true_pose)
    for seed in (1, 2, 3):
        shifted = outlier_blocks(small_survey, "footprint_shift", 0.2, rng=np.random.default_rng(seed))
        track = navigate_online(shifted, rough_map, SOUNDINGS, model=model)
        assert rmse(track, small_survey.true_pose) < 2.5 * clean  # measured: 1.3, 2.2, 1.5 x


def test_between_keys_the_output_uses_the_soundings_since_the_key(small_survey, rough_map):
    nav = GraphNavigator(small_survey, rough_map, SOUNDINGS)
    truth = small_survey.true_pose[:, :2]
    predicted, filtered, shrunk = [], [], []
    for k in range(small_survey.n_pings):
        tracking = k > 0 and not nav._is_key[k] and nav.terrain.tracking
        before = nav.predicted(k) if tracking else None
        pose, cov = nav.step()
        if tracking:
            predicted.append(np.sum((before[0][:2] - truth[k]) ** 2))
            filtered.append(np.sum((pose[:2] - truth[k]) ** 2))
            shrunk.append(np.trace(cov[:2, :2]) < np.trace(before[1][:2, :2]))
    assert len(filtered) > 100
    # measured: 0.41 against 0.48 m, the covariance smaller at 98 % of the pings
    assert np.sqrt(np.mean(filtered)) < 0.95 * np.sqrt(np.mean(predicted))
    assert np.mean(shrunk) > 0.9


def test_pings_with_no_map_under_them_do_not_end_tracking(small_survey, rough_map, tracked):
    start, end = tracked.terrain.episodes[0]
    gap = slice(start + 60, start + 80)
    assert end > gap.stop + 20
    depth = small_survey.beam_depth.copy()
    depth[gap] = np.nan  # no sounding: nothing to weigh, nothing that says the belief is wrong
    survey = dataclasses.replace(small_survey, beam_depth=depth)
    model = NavigationModel.from_survey(small_survey)
    nav = GraphNavigator(survey, rough_map, SOUNDINGS, model=model).run()
    assert any(a <= gap.start and b >= gap.stop + 20 for a, b in nav.terrain.episodes)


def test_tracking_starts_with_the_graph_converged(small_survey, rough_map):
    nav = GraphNavigator(small_survey, rough_map, SOUNDINGS)
    while not nav.terrain.tracking:
        nav.step()
    k = nav.index
    estimate = nav.isam.calculateEstimatePose2(k)
    nav.smoother.update(gtsam.NonlinearFactorGraph(), gtsam.Values(), gtsam.FixedLagSmootherKeyTimestampMap(),
                        [])
    again = nav.isam.calculateEstimatePose2(k)
    # one more Gauss-Newton step moves it by millimetres (measured: 0.1 mm; without the
    # iterations at the start, 4 cm)
    assert np.hypot(again.x() - estimate.x(), again.y() - estimate.y()) < 0.005


def test_the_tangent_plane_test_takes_a_belief_per_ping():
    from tangraph.graph.online_terrain import NONLINEAR_SIGMAS, tangent_departure

    north = east = np.arange(0.0, 200.0, 1.0)
    a = 0.01
    depth = 50.0 + a * (north[:, None] - 100.0) ** 2 + 0.0 * east[None, :]
    bathymetry = BathymetryMap(north, east, depth)
    spots = np.array([[100.0, 100.0], [90.0, 100.0]])
    n, e = spots[:, None, 0], spots[:, None, 1]
    variance = np.full((2, 1), 0.1**2)
    sigma = 2.0
    cov = np.diag([sigma**2, 1.0])
    one = tangent_departure(bathymetry, n, e, variance, cov)
    per_ping = tangent_departure(bathymetry, n, e, variance, np.stack([cov, cov]))
    assert per_ping == pytest.approx(one)
    # along north the map departs from its tangent plane by a d^2 at d = 2 sigma, along east not
    # (within the map's gradient, a finite difference of its cells: measured 1.36 against 1.28)
    expected = 2 * (a * (NONLINEAR_SIGMAS * sigma) ** 2) ** 2 / 0.1**2 / 4
    assert one == pytest.approx(expected, rel=0.1)
    # a ping whose position is known departs by nothing
    half = tangent_departure(bathymetry, n, e, variance, np.stack([cov, np.zeros((2, 2))]))
    assert half == pytest.approx(one / 2, rel=1e-9)


def test_the_tracking_exponents_are_the_filters_weighting_linearised():
    """A belief N(0, P) on a plane of gradient g: the filters' MBARI weighting of a large cloud
    drawn from it (tangraph.sensors.information_exponent) and the tracking factor's linearised
    exponent agree to Monte Carlo error; a perfect map weighs every sounding fully."""
    from tangraph.graph.online_terrain import OnlineTerrain
    from tangraph.sensors import information_exponent

    rng = np.random.default_rng(4)
    grad = np.array([[[0.05, 0.02], [0.2, -0.1], [0.01, 0.0]]])  # (1 ping, 3 soundings, 2)
    cov = np.array([[[9.0, 2.0], [2.0, 4.0]]])
    map_variance = np.full((1, 3), 0.04)
    exponent = OnlineTerrain._exponents(map_variance, grad, cov)
    cloud = rng.multivariate_normal(np.zeros(2), cov[0], 200_000)
    predicted = cloud @ grad[0].T  # the plane's depths under each sounding, (N, B)
    filters = information_exponent(predicted, np.full(len(cloud), 1.0 / len(cloud)), map_variance[0])
    np.testing.assert_allclose(exponent[0], filters, atol=0.01)
    assert exponent[0, 2] == 0.0 and 0.5 < exponent[0, 1] < 1.0  # flat: nothing; steep: most
    np.testing.assert_array_equal(OnlineTerrain._exponents(None, grad, cov), 1.0)


def test_a_keys_soundings_are_linearised_at_their_mode_not_at_the_prediction(small_survey, rough_map,
                                                                               monkeypatch):
    """The tracking factors and the output between keys linearise the soundings at the mode of
    the key's belief given them (Gauss-Newton from the prediction, an iterated Kalman update's
    point): from a prediction 3-4 m off on the rough map, the mode lands within 0.17-0.24 m of
    the truth, one linearisation at the prediction 0.76-0.88 m off (the posterior std is 0.1 m)."""
    from tangraph.graph import online_terrain as ot
    from tangraph.graph.calibration import to_world
    from tangraph.graph.terrain_factors import _evaluate

    nav = GraphNavigator(small_survey, rough_map, SOUNDINGS)
    while not (nav.terrain.tracking and nav._is_key[nav.index] and nav.index > 60):
        nav.step()
    prev = nav._key_of
    pings = np.arange(prev, prev + 10)
    terrain = ot._terrain(nav, prev, pings, nav.terrain.variance[pings])
    cov = 9.0 * nav._world(nav._key_pose, nav._key_joint)[1][:2, :2]  # a prediction as wide as it is off
    for off in ([3.0, 0.0], [0.0, 3.0], [-3.0, 2.0], [2.0, -3.0]):
        key = nav._key_pose.copy()
        key[:2] += off
        truth = small_survey.true_pose[prev, :2] - to_world(key, nav.calibration, nav.origin)[:2]
        first = _evaluate(terrain, rough_map, key[None], nav.calibration, nav.model.tide, jacobian=False,
                          noise=True)
        residual, grad, noise = first[0], first[3], first[-1]
        miss, full = {}, ot.FILTERED_ITERATIONS
        for iterations in (1, full):
            monkeypatch.setattr(ot, "FILTERED_ITERATIONS", iterations)
            shift, _ = ot._mode(nav, terrain, key[None], nav.model.tide, 0.0, cov, np.isfinite(residual),
                                np.ones(residual.shape), None, (residual, grad, noise))
            miss[iterations] = np.hypot(*(shift[:2] - truth))
        assert miss[full] < 0.4 * miss[1] and miss[full] < 0.3


@pytest.mark.parametrize("holds", [True, False])
def test_a_check_on_the_search_edge_ends_tracking_only_if_its_region_leaves_the_prediction_out(holds):
    """A check window whose best match lies on the search's edge contradicts the prediction only
    when its calibrated region leaves the search's centre (the prediction) out: on the drifting
    tide the windows' regions hold it while their best matches wander to the edge."""
    from types import SimpleNamespace

    from tangraph.fix_records import FixRecord
    from tangraph.graph.online_terrain import OnlineTerrain

    record = FixRecord.of(9, None, FixStatus.OUTSIDE_SEARCH, float("nan"), 40.0, "outside")
    fix = SimpleNamespace(quality=SimpleNamespace(holds_centre=holds))
    nav = SimpleNamespace(_is_end=np.ones(20, bool), fixes=[], window_first={},
                          _judge=lambda k, pose, joint, fix_: SimpleNamespace(record=record, fix=fix))
    terrain = OnlineTerrain(np.ones((20, 3)), tracking=True, found=True)
    taken = terrain.window(nav, 9, np.zeros(3), np.eye(5))
    assert terrain.tracking is holds and taken is not holds
    assert [r.status for r in nav.fixes] == ([FixStatus.CHECKED] if holds else [])


def test_tracking_reads_the_map_error_where_the_prediction_puts_the_soundings(small_survey, rough_map):
    """A tracking factor's soundings take the map's error where the key's estimate puts them
    (the count form, :func:`tangraph.sensors.placed_map_variances`), not at their dead-reckoned
    footprints: the same pings laid from a key moved onto a stretch known ten times worse read
    that stretch's error, with the counts of their own geometry."""
    from tangraph.graph.terrain_factors import footprints
    from tangraph.sensors import map_error, placed_map_variances

    east = np.broadcast_to(rough_map.east, rough_map.shape)
    cut = float(np.median(small_survey.true_pose[:, 1])) + 400.0
    prior = rough_map.replace(depth_std=np.where(east > cut, 1.0, 0.1), correlation_length=20.0)
    model = NavigationModel.from_survey(small_survey)
    nav = GraphNavigator(small_survey, prior, SOUNDINGS, model=model).run()
    terrain, key = nav.terrain, nav._key_of
    pings = np.arange(key, small_survey.n_pings)
    noise, error = model.sounding_std**2, map_error(prior, model)
    own_by_place = []
    for shift in (0.0, 600.0):  # the key's estimate as it is, and moved east onto the poor stretch
        nav._key_pose = nav._key_pose + np.array([0.0, shift, 0.0])
        laid, own = terrain.placed(nav, key, pings)
        north, east_ = footprints(laid, prior, nav._key_pose[None], nav.calibration)
        shared, expected_own = placed_map_variances(error, terrain.counts[pings], north, east_)
        seen = np.isfinite(laid.variance)
        np.testing.assert_allclose(laid.variance[seen], noise + shared[seen], rtol=1e-12)
        np.testing.assert_allclose(own, expected_own, rtol=1e-12)
        own_by_place.append(float(np.median(own[seen])))
    assert own_by_place[0] == pytest.approx(0.1**2, rel=0.05)
    assert own_by_place[1] == pytest.approx(1.0**2, rel=0.05)
