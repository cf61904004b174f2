"""The online navigator (tangraph.graph.online): iSAM2 on dead reckoning alone and on a small
simulated survey, its steps, outlier fixes, leaving the map, and the point-mass front end's windows
and tide."""

from __future__ import annotations

import dataclasses
import itertools

import gtsam
import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.eval import position_nees
from tangraph.graph import (
    GraphConfig,
    GraphNavigator,
    PoseGraph,
    dense_track,
    navigate_online,
    online_fixes,
    propagate,
    smooth_pose_graph,
)
from tangraph.graph.keyposes import translate_error
from tangraph.matching import tap_fix
from tangraph.sensors import (
    DeadReckoningModel,
    NavigationModel,
    increment_covariance,
    odometry,
    simulate_dead_reckoning,
)
from tangraph.survey import Survey
from tangraph.track import position_errors
from tests.graph.track_errors import rmse

CONFIG = GraphConfig(key_interval=20.0)


def dr_only_survey(model: DeadReckoningModel, n: int = 300) -> Survey:
    t = np.arange(n) * 2.0
    psi = 0.3 + 0.004 * t
    step = np.column_stack([np.cos(psi), np.sin(psi)]) * 2.0
    truth = np.column_stack([np.cumsum(step, axis=0) - step[0], psi])
    dr = simulate_dead_reckoning(t, truth, model, rng=np.random.default_rng(3))
    ones = np.ones((n, 1))
    return Survey(time=t, dr_pose=dr.pose, vehicle_depth=ones[:, 0], beam_forward=0 * ones,
                  beam_starboard=0 * ones, beam_depth=50 * ones, true_pose=truth,
                  meta={"settings": {"dead_reckoning": dataclasses.asdict(model)}})


def test_odometry_only_graph_reproduces_dr_with_its_covariance(rough_map):
    model = DeadReckoningModel(speed_noise=0.05, heading_walk=2e-4)
    survey = dr_only_survey(model)
    config = GraphConfig().replace(n_pings=10_000, ramp_pings=None, key_interval=30.0)
    nav = GraphNavigator(survey, rough_map, config, model=NavigationModel.from_dead_reckoning(
        model, initial_position_std=1e-3, odometry_min_std=1e-7, odometry_min_heading_std=1e-5,
        speed_scale_std=0.0, heading_bias_std=0.0)).run()
    online = nav.track()
    assert online.fixes == () and len(online.meta["key_indices"]) > 10
    np.testing.assert_allclose(online.pose, survey.dr_pose, atol=1e-6)
    cov0 = np.diag([1e-6, 1e-6, 1e-10])
    last = survey.n_pings - 1
    inc = increment_covariance(model, survey.time, survey.dr_pose, 0, last)
    expected = propagate(survey.dr_pose[0], cov0, odometry(survey.dr_pose, 0, last), inc)
    np.testing.assert_allclose(online.covariance[last], expected, rtol=2e-3, atol=1e-9)
    solution = smooth_pose_graph(nav.graph, config)
    np.testing.assert_allclose(solution.pose, survey.dr_pose[solution.keys], atol=1e-6)
    np.testing.assert_allclose(solution.covariance[-1, :3, :3], expected, rtol=2e-3, atol=1e-9)
    pose, cov = dense_track(survey, model, solution, nav.origin)
    np.testing.assert_allclose(pose, survey.dr_pose, atol=1e-6)
    np.testing.assert_allclose(cov[solution.keys], solution.covariance[:, :3, :3], atol=1e-12)


def test_isam2_containers_cleared_and_window_bounded(rough_map):
    survey = dr_only_survey(DeadReckoningModel(speed_noise=0.05, heading_walk=1e-4), n=120)
    config = GraphConfig().replace(n_pings=10_000, ramp_pings=None, key_interval=1.0, isam_window=None)
    nav = GraphNavigator(survey, rough_map, config)
    for _ in range(survey.n_pings):
        nav.step()
        assert nav.pending == (0, 0)
    # each factor added once: the start's heading and position, the calibration prior, the odometry
    assert nav.isam.getFactorsUnsafe().size() == 3 + len(nav.graph.odometry)
    assert nav.isam.calculateEstimate().size() == survey.n_pings + 1  # and the calibration
    windowed = GraphNavigator(survey, rough_map, config.replace(isam_window=5)).run()
    assert windowed.isam.calculateEstimate().size() <= 11
    np.testing.assert_allclose(windowed.track().pose, nav.track().pose, atol=1e-6)
    with pytest.raises(TangraphError, match="all have been processed"):
        nav.step()


def test_step_returns_copies_and_patches_are_laid_rigidly(small_survey, rough_map):
    nav = GraphNavigator(small_survey, rough_map, GraphConfig(key_interval=20.0))
    for _ in range(40):
        pose, cov = nav.step()
    pose[:] = 1e9
    cov[:] = 0.0
    assert np.all(nav.track().pose[39] < 1e8) and np.all(np.isfinite(nav.track().covariance[39]))
    laid = online_fixes.laid_poses(nav, 39, nav.track().pose[39])
    # the window has the DR's shape: every increment from its last ping is the DR's
    from tangraph.sensors import odometry

    np.testing.assert_allclose(odometry(laid, laid.shape[0] - 1, np.arange(laid.shape[0])),
                               odometry(small_survey.dr_pose[20:40], 19, np.arange(20)), atol=1e-9)
    np.testing.assert_allclose(laid[-1], nav.track().pose[39])


def test_a_model_is_required_when_the_survey_has_none(small_survey, rough_map):
    bare = small_survey.replace(meta={})
    with pytest.raises(TangraphError, match="NavigationModel"):
        navigate_online(bare, rough_map)
    track = navigate_online(bare, rough_map, GraphConfig(key_interval=20.0),
                            model=NavigationModel.from_survey(small_survey))
    assert track.meta["n_fixes_accepted"] > 0


def test_a_fix_window_may_end_at_the_first_ping(small_survey, rough_map):
    config = GraphConfig().replace(n_pings=1, fix_spacing=50, key_interval=20.0)
    track = navigate_online(small_survey, rough_map, config)
    assert [f.index for f in track.fixes] == [0, 50, 100, 150, 200]


def test_gtsam_indeterminant_error_is_translated():
    graph = PoseGraph()
    graph.add_pose(0, 0.0, [0, 0, 0])
    graph.add_pose(7, 1.0, [1, 0, 0])
    graph.add_pose_prior(0, [0, 0, 0], np.eye(3))
    error = translate_error(RuntimeError("Indeterminate linear system detected while working near variable\n"
                                    "7 (Symbol: 7)."), graph)
    assert isinstance(error, TangraphError) and "ping 7" in str(error)
    determined = PoseGraph()
    determined.add_pose(0, 0.0, [0, 0, 0])
    determined.add_pose_prior(0, [0, 0, 0], np.eye(3))
    tide = translate_error(RuntimeError(f"Indeterminate system near variable\n{int(gtsam.symbol('t', 0))}"),
                           determined)
    assert str(tide) == "the pose graph is indeterminant (ill-conditioned) near the tide (t0)"
    other = RuntimeError("something else")
    assert translate_error(other, graph) is other


def outlier_fixes(survey, bathymetry, config, rate: float, rng) -> dict:
    """Wrong but confident fixes at ``rate`` of the window ends: the genuine fix moved 15-40 m."""
    ends = np.arange(config.fixes.n_pings - 1, survey.n_pings, config.spacing)
    chosen = rng.choice(ends[1:], size=max(1, round(rate * ends.size)), replace=False)
    fixes = {}
    for k in chosen:
        genuine = tap_fix(survey, bathymetry, int(k), config.fixes.n_pings,
                          dataclasses.replace(config.fixes.tap, half_width=30.0),
                          prior=survey.true_pose[k, :2])
        angle, distance = rng.uniform(0, 2 * np.pi), rng.uniform(15.0, 40.0)
        fixes[int(k)] = dataclasses.replace(
            genuine, position=genuine.position + distance * np.array([np.cos(angle), np.sin(angle)]))
    return fixes


@pytest.mark.parametrize("rate", [0.1, 0.3])
def test_outlier_fixes_do_not_pull_the_track(small_survey, rough_map, rate):
    config = GraphConfig(key_interval=20.0)
    truth = small_survey.true_pose
    clean = GraphNavigator(small_survey, rough_map, config).run()
    bad = outlier_fixes(small_survey, rough_map, config, rate, np.random.default_rng(int(rate * 100)))
    nav = GraphNavigator(small_survey, rough_map, config)
    for k in range(small_survey.n_pings):
        nav.step(fix=bad.get(k))
    polluted = nav.track()
    refused = [f for f in polluted.fixes if f.index in bad]
    assert all(not f.accepted for f in refused)
    assert rmse(polluted, truth) <= 1.5 * rmse(clean.track(), truth)
    solve = {n: smooth_pose_graph(x.graph, config) for n, x in (("clean", clean), ("polluted", nav))}
    errors = {}
    for name, solution in solve.items():
        pose, _ = dense_track(small_survey, clean.white, solution, clean.origin)
        errors[name] = np.sqrt(np.mean(np.sum((pose[:, :2] - truth[:, :2]) ** 2, axis=1)))
    assert errors["polluted"] <= 1.5 * errors["clean"]


def test_robust_kernel_alone_limits_an_outlier(small_survey, rough_map):
    config = GraphConfig().replace(key_interval=20.0, gate_probability=None, confirm_probability=None,
                         lost_windows=None)
    truth = small_survey.true_pose
    bad = outlier_fixes(small_survey, rough_map, config, 0.1, np.random.default_rng(5))
    tracks = {}
    for kernel in ("huber", "cauchy", "none"):
        model = NavigationModel.from_survey(small_survey, robust_kernel=kernel)
        nav = GraphNavigator(small_survey, rough_map, config, model=model)
        for k in range(small_survey.n_pings):
            nav.step(fix=bad.get(k))
        tracks[kernel] = rmse(nav.track(), truth)
    assert tracks["huber"] < tracks["none"] and tracks["cauchy"] < tracks["none"]


@pytest.mark.parametrize("cov", [np.zeros((2, 2)), -np.eye(2), np.full((2, 2), np.nan)])
def test_bad_fix_covariance_in_a_step_is_refused(small_survey, rough_map, cov):
    config = GraphConfig().replace(key_interval=20.0, n_pings=10, fix_spacing=None)
    nav = GraphNavigator(small_survey, rough_map, config)
    for _ in range(29):
        nav.step()
    fix = tap_fix(small_survey, rough_map, 29, config.fixes.n_pings, config.fixes.tap,
                  prior=small_survey.true_pose[29, :2])
    with pytest.raises(TangraphError, match=r"fix at ping 29 \(window 20\.\.29\)"):
        nav.step(fix=dataclasses.replace(fix, covariance=cov))


def _half_map(bathymetry):
    """The map without its depths north of 600 m: the small survey leaves it about halfway."""
    depth = np.array(bathymetry.depth)
    depth[bathymetry.north > 600.0, :] = np.nan
    return dataclasses.replace(bathymetry, depth=depth, name="half")


def test_leaving_the_map_the_graph_stays_honest(small_survey, rough_map):
    half = _half_map(rough_map)
    off = small_survey.true_pose[:, 0] > 620.0
    track = navigate_online(small_survey, half, CONFIG)
    nees = position_nees(track, small_survey.true_pose)
    assert off.sum() > 50 and np.all(nees[off] <= 20.0)
    spread = track.covariance[off, 0, 0] + track.covariance[off, 1, 1]
    assert np.all(np.diff(spread) >= -1e-9)  # off the map only the DR model speaks: it grows
    assert track.meta["lost_episodes"] == []  # no fix is made there, so nothing says "lost"


@pytest.mark.slow
def test_leaving_the_map_the_final_nees_is_in_its_band_over_seeds(rough_map):
    from tangraph.eval import anees_band
    from tangraph.sim.scenario import simulate
    from tests.graph.conftest import small_scenario

    half = _half_map(rough_map)
    final = []
    for seed in range(61, 67):
        survey = simulate(small_scenario(), rng=np.random.default_rng(seed), bathymetry=rough_map, seed=seed)
        final.append(position_nees(navigate_online(survey, half, CONFIG), survey.true_pose)[-1])
    low, high = anees_band(len(final))
    assert low <= np.mean(final) <= high


def test_the_online_graph_on_the_point_mass_front_end(small_survey, rough_map):
    config = GraphConfig().replace(front_end="pmf")
    nav = GraphNavigator(small_survey, rough_map, config)
    track = nav.run().track()
    ends = sorted(nav.window_first)
    firsts = [nav.window_first[k] for k in ends]
    assert firsts[0] == 0 and firsts[1:] == [k + 1 for k in ends[:-1]]  # no ping in two windows
    dr = np.hypot(*(small_survey.dr_pose[:, :2] - small_survey.true_pose[:, :2]).T)
    errors = position_errors(track, small_survey.true_pose)
    assert np.sqrt(np.mean(errors**2)) < 0.25 * np.sqrt(np.mean(dr**2))  # measured: 0.16
    assert track.meta["n_fixes_accepted"] > 0.7 * len(track.fixes)
    again = navigate_online(small_survey, rough_map, config)  # deterministic
    np.testing.assert_array_equal(again.pose, track.pose)


def test_an_ambiguous_window_grows_and_used_windows_share_no_ping(rough_map):
    from conftest import small_scenario

    from tangraph.sim.scenario import simulate

    # a wide start: the first windows' soundings fit several places within the prediction's reach
    survey = simulate(small_scenario(start_position_std=30.0), rng=np.random.default_rng(61),
                      bathymetry=rough_map, seed=61)
    nav = GraphNavigator(survey, rough_map, GraphConfig().replace(front_end="pmf")).run()
    lengths = {k: k - first + 1 for k, first in nav.window_first.items() if k <= nav.index}
    assert max(lengths.values()) > 3 and max(lengths.values()) <= nav.config.fixes.n_pings
    used = sorted((nav.window_first[r.index], r.index) for r in nav.fixes if r.accepted)
    assert all(a[1] < b[0] for a, b in itertools.pairwise(used))  # disjoint
    track = nav.track()
    errors = position_errors(track, survey.true_pose)
    dr = np.hypot(*(survey.dr_pose[:, :2] - survey.true_pose[:, :2]).T)
    # measured: 0.22 m over the second half against a DR RMSE of 7.6 m
    assert np.sqrt(np.mean(errors[len(errors) // 2:] ** 2)) < 0.1 * np.sqrt(np.mean(dr**2))


def test_the_online_graph_learns_the_tide_from_its_windows(rough_map):
    import dataclasses

    from conftest import small_scenario

    from tangraph.sim.scenario import simulate

    scenario = small_scenario()
    scenario = dataclasses.replace(scenario, sonar=dataclasses.replace(scenario.sonar, tide=1.5))
    survey = simulate(scenario, rng=np.random.default_rng(62), bathymetry=rough_map, seed=62)
    track = navigate_online(survey, rough_map, GraphConfig().replace(front_end="pmf"))
    tide = track.meta["tide"]
    assert tide["tide_std"] < 0.05  # from the prior's 3 m
    assert abs(tide["tide"] - 1.5) < 3 * tide["tide_std"] + 0.01
    # told the tide exactly, the graph holds no tide variable
    from tangraph.sensors import NavigationModel

    model = dataclasses.replace(NavigationModel.from_survey(survey), tide=1.5, tide_std=0.0)
    known = navigate_online(survey, rough_map, GraphConfig().replace(front_end="pmf"), model=model)
    assert "tide" not in known.meta


def test_a_key_added_by_odometry_alone_takes_the_propagated_marginal(small_survey, rough_map, monkeypatch):
    """Where an update adds only the odometry into a key, its joint covariance with the
    calibration is the latest key's carried by the increment, not the Bayes tree's joint marginal:
    the same track and covariances as with the marginal at every key (to the relinearisation's
    differences), for a fraction of the cost."""
    config = GraphConfig().replace(key_interval=5.0)
    used = []
    real = GraphNavigator._odometry_only

    def counted(self, prev, extra, predicted):
        joint = real(self, prev, extra, predicted)
        used.append(joint is not None)
        return joint

    monkeypatch.setattr(GraphNavigator, "_odometry_only", counted)
    fast = GraphNavigator(small_survey, rough_map, config).run().track()
    monkeypatch.setattr(GraphNavigator, "_odometry_only", lambda self, prev, extra, predicted: None)
    exact = GraphNavigator(small_survey, rough_map, config).run().track()
    assert fast.meta["n_fixes_accepted"] == exact.meta["n_fixes_accepted"] > 3
    assert 0.5 < np.mean(used) < 1.0  # most keys carried, those with a fix from the Bayes tree
    np.testing.assert_allclose(fast.pose, exact.pose, atol=1e-3)
    std_fast = np.sqrt(np.trace(fast.covariance[:, :2, :2], axis1=1, axis2=2))
    std_exact = np.sqrt(np.trace(exact.covariance[:, :2, :2], axis1=1, axis2=2))
    np.testing.assert_allclose(std_fast, std_exact, rtol=1e-3)
    assert np.any(std_fast != std_exact)  # carried, not asked of the Bayes tree, somewhere
