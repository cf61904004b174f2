"""The batch smoother (tangraph.graph.smoother): least squares by hand, the track against the online
navigator's and the truth, re-matching, its robust solve on wrong fixes and a wrong start, and the
pings it leaves lost."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.eval import track_metrics
from tangraph.graph import (
    FixRecord,
    FixStatus,
    GraphConfig,
    PoseGraph,
    navigate_online,
    smooth_pose_graph,
    smooth_survey,
)
from tangraph.sim.faults import offset_start
from tests.graph.track_errors import mean_nees, rmse

CONFIG = GraphConfig(key_interval=20.0)


def linear_graph():
    """Three poses heading north with the heading pinned: a linear problem in the positions."""
    graph = PoseGraph(robust_kernel="none", min_std=1e-9, min_heading_std=1e-9)
    truth = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [20.0, 0.0, 0.0]])
    for k, p in enumerate(truth):
        graph.add_pose(k, float(k), p + np.array([1.0, -1.0, 0.0]))
    p0_cov = np.diag([4.0, 9.0, 1e-12])
    graph.add_pose_prior(0, [0.5, 0.2, 0.0], p0_cov)
    q01, q12 = np.diag([1.0, 0.25, 1e-12]), np.array([[0.5, 0.1, 0.0], [0.1, 0.3, 0.0], [0.0, 0.0, 1e-12]])
    graph.add_odometry(0, 1, [10.2, -0.1, 0.0], q01)
    graph.add_odometry(1, 2, [9.7, 0.3, 0.0], q12)
    f1, f2 = np.array([[2.0, 0.5], [0.5, 1.0]]), np.diag([0.8, 1.5])
    graph.add_position_fix(1, [10.4, 0.6], f1)
    graph.add_position_fix(2, [19.1, -0.2], f2)
    # The same problem by hand: unknowns (n0, e0, n1, e1, n2, e2), weighted least squares.
    eye, zero = np.eye(2), np.zeros((2, 2))
    rows = [(np.hstack([eye, zero, zero]), [0.5, 0.2], p0_cov[:2, :2]),
            (np.hstack([-eye, eye, zero]), [10.2, -0.1], q01[:2, :2]),
            (np.hstack([zero, -eye, eye]), [9.7, 0.3], q12[:2, :2]),
            (np.hstack([zero, eye, zero]), [10.4, 0.6], f1),
            (np.hstack([zero, zero, eye]), [19.1, -0.2], f2)]
    info = sum(a.T @ np.linalg.inv(c) @ a for a, _, c in rows)
    vector = sum(a.T @ np.linalg.inv(c) @ np.asarray(z) for a, z, c in rows)
    cov = np.linalg.inv(info)
    return graph, (cov @ vector).reshape(3, 2), cov


def test_smoother_matches_hand_computed_least_squares():
    graph, expected, cov = linear_graph()
    solution = smooth_pose_graph(graph, GraphConfig())
    np.testing.assert_allclose(solution.pose[:, :2], expected, atol=1e-6)
    for k in range(3):
        np.testing.assert_allclose(solution.covariance[k, :2, :2], cov[2 * k : 2 * k + 2, 2 * k : 2 * k + 2],
                                   rtol=1e-5, atol=1e-9)


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


def test_the_smoother_drops_a_wrong_start_prior(small_survey, rough_map):
    """The DR starts 80 m off while the model says 10 m: the fixes outvote the start prior."""
    survey = offset_start(small_survey, [60.0, -53.0])
    track = smooth_survey(survey, rough_map, GraphConfig(key_interval=20.0))
    error = np.hypot(*(track.pose[:, :2] - survey.true_pose[:, :2]).T)
    assert track.meta["start_prior"] == "outlier"
    assert np.sqrt(np.mean(error**2)) < 3.0
    plain = smooth_survey(survey, rough_map, GraphConfig().replace(key_interval=20.0, robust_solve="none"))
    assert plain.meta["start_prior"] == "kept"


def test_gnc_keeps_the_start_prior_where_nothing_else_ties_the_graph():
    graph = PoseGraph(np.array([0.02, 0.03]))
    graph.add_pose(0, 0.0, [0.0, 0.0, 0.0])
    graph.add_start(0, [0.0, 0.0, 0.0], 10.0, 0.01)
    graph.add_pose(10, 10.0, [10.0, 0.0, 0.0])
    graph.add_odometry(0, 10, [10.0, 0.0, 0.0], np.diag([0.1, 0.1, 1e-4]))
    graph.add_position_fix(10, [500.0, 0.0], np.eye(2))  # one fix cannot outvote the start
    from tangraph.graph.smoother import _gnc_inliers

    inlier, keep_start = _gnc_inliers(graph, graph.fixes, GraphConfig(), np.asarray(graph.initial),
                                      np.zeros(2))
    assert keep_start and inlier.tolist() == [False]  # the start stays; the wild fix goes


def test_the_smoother_relocalises_the_whole_track(wrong_start, rough_map):
    track = smooth_survey(wrong_start, rough_map, CONFIG)
    errors = np.hypot(*(track.pose[:, :2] - wrong_start.true_pose[:, :2]).T)
    assert track.meta["start_prior"] == "outlier" and np.sqrt(np.mean(errors**2)) < 3.0
    assert track_metrics(track, wrong_start.true_pose)["confident_wrong"] == 0.0
    assert not track.lost.any()  # the smoother's answer holds from the first ping


def test_without_the_robust_solve_the_smoother_keeps_the_widened_start(wrong_start, rough_map):
    """With ``robust_solve="none"`` the smoother solves the online graph as it is: the start
    prior the lost navigator widened stays widened, so the fixes that relocalised it hold."""
    track = smooth_survey(wrong_start, rough_map, CONFIG.replace(robust_solve="none"))
    errors = np.hypot(*(track.pose[:, :2] - wrong_start.true_pose[:, :2]).T)
    assert np.sqrt(np.mean(errors**2)) < 5.0


def test_a_forward_pass_lost_to_the_end_leaves_only_the_smoothers_unfixed_tail_lost(wrong_start, rough_map):
    """An online navigator that never relocalises is lost to the end; the smoother, which weighs
    every fix again, flags only the pings after the last fix it kept, and keeps the forward
    pass's episodes apart."""
    config = CONFIG.replace(relocalise_fixes=10_000)
    online = navigate_online(wrong_start, rough_map, config)
    assert online.meta["lost_episodes"][-1]["end"] is None and online.lost[-1]
    track = smooth_survey(wrong_start, rough_map, config)
    last = max(f.index for f in track.fixes if f.accepted)
    assert track.meta["lost_steps"] == list(range(last + 1, wrong_start.n_pings))
    assert track.meta["forward_lost_episodes"] == online.meta["lost_episodes"]
    assert len(track.meta["lost_episodes"]) == (1 if track.meta["lost_steps"] else 0)


def test_the_batch_smoother_weighs_tap_fixes_whatever_the_front_end(small_survey, rough_map):
    from tangraph.graph import smooth_survey

    tap = smooth_survey(small_survey, rough_map, GraphConfig())
    other = smooth_survey(small_survey, rough_map, GraphConfig().replace(front_end="pmf"))
    np.testing.assert_array_equal(other.pose, tap.pose)
    assert other.meta["config"]["online"]["front_end"] == "tap"  # the record says what was run
