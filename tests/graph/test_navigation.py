"""Online iSAM2 navigator and batch smoother on dead reckoning alone and on a small simulated survey."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.graph import (
    FixRecord,
    FixStatus,
    GraphConfig,
    GraphNavigator,
    dense_track,
    load_graph_config,
    navigate_online,
    propagate,
    smooth_pose_graph,
    smooth_survey,
)
from tangraph.graph.fixes import search_half_width, search_step
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import TapConfig, tap_fix
from tangraph.sensors import (
    DeadReckoningModel,
    NavigationModel,
    increment_covariance,
    odometry,
    simulate_dead_reckoning,
)
from tangraph.survey import Survey
from tangraph.track import position_errors


def rmse(track, truth) -> float:
    return float(np.sqrt(np.mean(position_errors(track, truth) ** 2)))


def mean_nees(track, truth) -> float:
    err = track.pose[:, :2] - truth[:, :2]
    cov = track.covariance[:, :2, :2]
    return float(np.mean([e @ np.linalg.solve(c, e) for e, c in zip(err, cov, strict=True)]))


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


def test_recovers_truth_better_than_dead_reckoning(small_survey, rough_map):
    config = GraphConfig(key_interval=20.0)
    online = navigate_online(small_survey, rough_map, config)
    smoothed = smooth_survey(small_survey, rough_map, config)
    truth = small_survey.true_pose
    dr = float(np.sqrt(np.mean(np.sum((small_survey.dr_pose[:, :2] - truth[:, :2]) ** 2, axis=1))))
    assert rmse(online, truth) < dr / 3 and rmse(smoothed, truth) < dr / 4
    assert rmse(smoothed, truth) <= rmse(online, truth)
    for track, method in ((online, "isam2"), (smoothed, "smoother")):
        assert track.method == method and track.n_poses == small_survey.n_pings
        meta = track.meta
        assert meta["n_fixes_accepted"] + meta["n_fixes_rejected"] == len(track.fixes) > 10
        assert meta["n_fixes_accepted"] >= 0.8 * len(track.fixes)
        assert isinstance(track.fixes[0], FixRecord) and isinstance(track.fixes[0].status, FixStatus)
        assert all(f.index in meta["key_indices"] for f in track.fixes)
        # one run's ANEES over its correlated poses has no chi-square band; the bounds cover
        # what 200 seeds of this set-up measured (1st-99th percentile: isam2 1.20-4.82, smoother
        # 0.85-2.50; extremes 1.17-5.17 and 0.74-2.52) with a margin. Their means over seeds are
        # checked in test_covariances_over_seeds_match_the_measured_anees (slow).
        lo, hi = {"isam2": (1.0, 6.0), "smoother": (0.6, 3.0)}[method]
        assert lo < mean_nees(track, truth) < hi, (method, mean_nees(track, truth))
    assert {"total", "per_step", "per_step_p99"} <= set(online.timings)
    # heading bias (1 deg) is estimated: the smoothed heading error is well below it
    assert np.abs(np.mean(smoothed.pose[:, 2] - truth[:, 2])) < np.deg2rad(0.5)


def test_rematch_converges(small_survey, rough_map):
    """Re-matching stops by itself, before a generous cap, once no fix moves by more than the
    tolerance (an oscillating re-match would run to the cap): here within 1 cm after 5 rounds,
    the moves shrinking each round (measured: 2 rounds to 5 cm, 8 to 1 mm); it moves the fixes
    and does not make the track worse."""
    config = GraphConfig().replace(key_interval=20.0, rematch_iterations=10, rematch_tolerance=0.01)
    smoothed = smooth_survey(small_survey, rough_map, config)
    single = smooth_survey(small_survey, rough_map, config.replace(rematch_iterations=0))
    done = smoothed.meta["rematch_iterations"]
    assert 1 <= done < 10 and single.meta["rematch_iterations"] == 0
    # re-matched patches are laid with the smoothed poses: the fixes move, and the track does not get worse
    moved = [np.hypot(a.north - b.north, a.east - b.east)
             for a, b in zip(smoothed.fixes, single.fixes, strict=True)
             if a.accepted and b.accepted]
    assert max(moved) > 0
    assert rmse(smoothed, small_survey.true_pose) <= 1.05 * rmse(single, small_survey.true_pose) < 1.5


def test_a_rematch_has_moved_when_a_fix_moves_beyond_the_tolerance_or_changes_its_verdict():
    from tangraph.fix_records import FixRecord, FixStatus
    from tangraph.graph.smoother import _moved

    def record(north, status=FixStatus.ACCEPTED, index=10):
        return FixRecord(index, north, 0.0, 1.0, 0.0, 1.0, status, 0.5, 50.0)

    before = [record(0.0), record(5.0, index=20)]
    assert not _moved(before, [record(0.4), record(5.0, index=20)], 0.5)
    assert _moved(before, [record(0.6), record(5.0, index=20)], 0.5)
    assert _moved(before, [record(0.0, FixStatus.GATE), record(5.0, index=20)], 0.5)
    assert _moved(before, [record(0.0), record(5.0, index=30)], 0.5)  # a window it had not made


def test_step_returns_copies_and_patches_are_laid_rigidly(small_survey, rough_map):
    nav = GraphNavigator(small_survey, rough_map, GraphConfig(key_interval=20.0))
    for _ in range(40):
        pose, cov = nav.step()
    pose[:] = 1e9
    cov[:] = 0.0
    assert np.all(nav.track().pose[39] < 1e8) and np.all(np.isfinite(nav.track().covariance[39]))
    laid = nav._laid(39, nav.track().pose[39])
    # the window has the DR's shape: every increment from its last ping is the DR's
    from tangraph.sensors import odometry

    np.testing.assert_allclose(odometry(laid, laid.shape[0] - 1, np.arange(laid.shape[0])),
                               odometry(small_survey.dr_pose[20:40], 19, np.arange(20)), atol=1e-9)
    np.testing.assert_allclose(laid[-1], nav.track().pose[39])


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


def test_a_model_is_required_when_the_survey_has_none(small_survey, rough_map):
    bare = small_survey.replace(meta={})
    with pytest.raises(TangraphError, match="NavigationModel"):
        navigate_online(bare, rough_map)
    track = navigate_online(bare, rough_map, GraphConfig(key_interval=20.0),
                            model=NavigationModel.from_survey(small_survey))
    assert track.meta["n_fixes_accepted"] > 0


@pytest.mark.parametrize(("changes", "named"), [
    ({"front_end": "ekf"}, "OnlineConfig.front_end"), ({"key_interval": 0.0}, "GraphConfig.key_interval"),
    ({"n_pings": 0}, "FixConfig.n_pings"), ({"gate_probability": 1.5}, "FixConfig.gate_probability"),
    ({"isam_window": 1}, "OnlineConfig.isam_window"),
    ({"min_half_width_cells": 10.0, "max_half_width_cells": 5.0}, "FixConfig: max_half_width_cells"),
    ({"relinearize_threshold": float("nan")}, "OnlineConfig.relinearize_threshold"),
    ({"ramp_pings": 0}, "FixConfig.ramp_pings"),
    ({"tap": TapConfig(half_width=30.0)}, "FixConfig: tap.half_width"),
    ({"tap": TapConfig(step=2.0), "tap_step_cells": 1.0}, "FixConfig: tap.step"),
    ({"rematch_iterations": -1}, "BatchConfig.rematch_iterations"),
    ({"gnc_probability": 1.0}, "BatchConfig.gnc_probability"),
    ({"n_ping": 20}, "unknown GraphConfig field 'n_ping'"),
    ({"optimizer": "lm"}, "GraphConfig.optimizer is no longer a setting"),
])
def test_config_is_validated(changes, named):
    """Every part checks its fields, naming the part and the field."""
    with pytest.raises(TangraphError, match=named):
        GraphConfig().replace(**changes)


def test_config_honours_what_it_is_given():
    """A fixed half-width and a step in metres are used as given; a removed key is refused by
    name, with where its job went."""
    config = GraphConfig().replace(half_width_rule="fixed", tap=TapConfig(half_width=30.0, step=2.0))
    bathy = BathymetryMap(np.arange(5) * 5.0, np.arange(5) * 5.0, np.zeros((5, 5)))
    assert search_half_width(config, bathy, np.eye(2) * 1e4) == 30.0
    assert search_step(config, bathy) == 2.0
    assert search_step(GraphConfig().replace(tap_step_cells=1.0), bathy) == 5.0
    removed = r"cfg.toml: GraphConfig.optimizer is no longer a setting: .*gauss_newton"
    with pytest.raises(TangraphError, match=removed):
        GraphConfig.from_mapping({"optimizer": "lm"}, "cfg.toml")


@pytest.mark.slow
def test_covariances_over_seeds_match_the_measured_anees(rough_map):
    """Over 20 seeded surveys both tracks beat DR, and the mean over the seeds of each track's
    ANEES lies within 3 Monte Carlo standard errors of its value measured over 200 seeds.

    A consistent covariance gives an expected ANEES of 2 (each pose's NEES has mean 2, however
    correlated the poses are), but neither estimator is consistent here, and the bands say so
    rather than hide it: over seeds 0-199 the smoother's ANEES averages 1.48 (standard deviation
    of one run's 0.36, so 1.48 +- 0.03: under-confident, its covariance 1.35 times too large in
    the NEES sense) and iSAM2's 2.54 (sd 0.77, 2.54 +- 0.05: over-confident by a factor 1.27).
    With R = 20 runs the standard error of the mean is sd / sqrt(20): 0.08 and 0.17, so the
    bands are 1.48 +- 0.24 and 2.54 +- 0.52 (20-seed block means measured: 1.39-1.63 and
    2.19-2.83). A change that made either consistent (ANEES 2) fails this test on purpose:
    move the band to 2 +- 3 sd / sqrt(20) then.

    The final pose's NEES, a chi-square(2) sample per run if the covariance is right, averages
    2.77 (smoother) and 2.92 (isam2) over the 200 seeds, +-0.14 for chi-square(2): over-confident
    at the end by a factor ~1.4 too; 20 runs (standard error 0.6 at the measured spread) cannot
    resolve that, so it is not asserted here.
    """
    from tangraph.sim.scenario import simulate
    from tests.graph.conftest import small_scenario

    runs = 20
    anees = {"isam2": [], "smoother": []}
    for seed in range(runs):
        survey = simulate(small_scenario(), rng=np.random.default_rng(100 + seed), bathymetry=rough_map)
        truth = survey.true_pose
        dr = float(np.sqrt(np.mean(np.sum((survey.dr_pose[:, :2] - truth[:, :2]) ** 2, axis=1))))
        config = GraphConfig(key_interval=20.0)
        for track in (navigate_online(survey, rough_map, config), smooth_survey(survey, rough_map, config)):
            assert rmse(track, truth) < dr / 3
            anees[track.method].append(mean_nees(track, truth))
    for method, measured, sd in (("smoother", 1.48, 0.36), ("isam2", 2.54, 0.77)):
        half = 3 * sd / np.sqrt(runs)
        assert abs(np.mean(anees[method]) - measured) < half, (method, np.mean(anees[method]))


def test_a_fix_window_may_end_at_the_first_ping(small_survey, rough_map):
    config = GraphConfig().replace(n_pings=1, fix_spacing=50, key_interval=20.0)
    track = navigate_online(small_survey, rough_map, config)
    assert [f.index for f in track.fixes] == [0, 50, 100, 150, 200]


def test_a_map_error_shared_by_the_soundings_widens_every_fix(small_survey, rough_map):
    """The TAP part of a fix grows by the map error its window's soundings share with the
    survey's others (the terrain model's row-sum bound), the more so the longer its range."""
    config = GraphConfig(key_interval=20.0)
    model = NavigationModel.from_survey(small_survey)
    plain = navigate_online(small_survey, rough_map, config, model=model).fixes[0]
    sizes = []
    for length in (5.0, 20.0):
        wrong = model.replace(map_std=0.2, map_correlation_length=length)
        first = navigate_online(small_survey, rough_map, config, model=wrong).fixes[0]
        assert first.index == plain.index
        sizes.append(np.trace(first.covariance))
    assert np.trace(plain.covariance) < sizes[0] < sizes[1], (np.trace(plain.covariance), sizes)


def test_graph_config_from_a_toml_file(tmp_path):
    """A file gives the parts as tables; a part's field at the top level is refused naming its
    table, a moved or unknown key by name."""
    path = tmp_path / "graph.toml"
    path.write_text('[graph]\nkey_interval = 30.0\n[graph.fixes]\nn_pings = 40\n[graph.fixes.tap]\n'
                    'criterion = "msd"\n[graph.online]\nfront_end = "pmf"\n[graph.batch]\n'
                    'smoother_terrain = "field"\n')
    config = load_graph_config(path)
    assert (config.key_interval, config.fixes.n_pings, config.fixes.tap.criterion.value) == (30.0, 40, "msd")
    assert (config.online.front_end, config.batch.smoother_terrain) == ("pmf", "field")
    assert config == GraphConfig.from_mapping(config.as_dict())  # the track's metadata reads back
    assert config.spacing == config.window == 3  # the point-mass front end's windows
    path.write_text('[graph]\nn_pings = 60\n')
    with pytest.raises(TangraphError, match=r"graph.toml: GraphConfig.n_pings is now in the fixes part"):
        load_graph_config(path)
    with pytest.raises(TangraphError, match=r"GraphConfig.lost_windows is now in the online part"):
        GraphConfig.from_mapping({"lost_windows": 3}, "cfg.toml")
    with pytest.raises(TangraphError, match="cfg.toml: GraphConfig.batch must be a table"):
        GraphConfig.from_mapping({"batch": 3}, "cfg.toml")
    path.write_text('[graph]\nrobust_kernel = "cauchy"\n')
    moved = r"graph.toml: GraphConfig.robust_kernel .* NavigationModel.robust_kernel"
    with pytest.raises(TangraphError, match=moved):
        load_graph_config(path)
    path.write_text('[graph.fixes.tap]\ncriterio = "msd"\n')
    with pytest.raises(TangraphError, match="unknown TapConfig field 'criterio'"):
        load_graph_config(path)
    path.write_text('[graph.online]\nn_pings = 3\n')
    with pytest.raises(TangraphError, match="unknown OnlineConfig field 'n_pings'"):
        load_graph_config(path)
    path.write_text("[graph]\nkey_interval = 60.0\n[other]\nx = 1\n")
    with pytest.raises(TangraphError, match="keys outside \\[graph\\]: other"):
        load_graph_config(path)
