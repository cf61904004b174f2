"""The online navigator's side of the fix policy (tangraph.graph.lost): it knows when it is lost,
widens its search, relocalises on agreeing fixes, holds a surprising fix until another agrees, flags
what it could not trust, and never reports a confident wrong pose."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.eval import position_nees, track_metrics
from tangraph.graph import FixStatus, GraphConfig, GraphNavigator, navigate_online
from tangraph.matching import tap_fix

CONFIG = GraphConfig(key_interval=20.0)


def test_a_wrong_start_is_found_lost_and_relocalised(wrong_start, rough_map):
    track = navigate_online(wrong_start, rough_map, CONFIG)
    episodes = track.meta["lost_episodes"]
    assert len(episodes) >= 1 and episodes[0]["start"] == 0 and episodes[0]["end"] is not None
    assert episodes[0]["breaks"][0] >= 40.0  # the belief was widened by at least the first search
    statuses = {f.status for f in track.fixes}
    assert FixStatus.OUTSIDE_SEARCH in statuses
    after = episodes[-1]["end"] + 1
    errors = np.hypot(*(track.pose[after:, :2] - wrong_start.true_pose[after:, :2]).T)
    assert np.sqrt(np.mean(errors**2)) < 5.0
    nees = position_nees(track, wrong_start.true_pose)
    assert np.all(track.lost | (nees <= 20.0))  # never confidently wrong
    assert track_metrics(track, wrong_start.true_pose)["confident_wrong"] == 0.0


def test_without_the_lost_test_the_wrong_start_is_a_confident_wrong_answer(wrong_start, rough_map):
    track = navigate_online(wrong_start, rough_map, CONFIG.replace(lost_windows=None))
    assert track.meta["lost_episodes"] == [] and not track.lost.any()
    assert track_metrics(track, wrong_start.true_pose)["confident_wrong"] > 0.5


def test_a_clean_survey_is_never_lost(small_survey, rough_map):
    track = navigate_online(small_survey, rough_map, CONFIG)
    assert track.meta["lost_episodes"] == [] and track.meta["n_lost"] == 0


def _fix_at(survey, bathymetry, k, offset):
    fix = tap_fix(survey, bathymetry, k, CONFIG.fixes.n_pings,
                  dataclasses.replace(CONFIG.fixes.tap, half_width=30.0),
                  prior=survey.true_pose[k, :2])
    return dataclasses.replace(fix, position=survey.true_pose[k, :2] + np.asarray(offset, float),
                               covariance=np.eye(2))


def _navigator_at(survey, bathymetry, k):
    nav = GraphNavigator(survey, bathymetry, CONFIG)
    for _ in range(k):
        nav.step()
    return nav


@pytest.mark.parametrize(("second", "status"), [
    ((2.9, 0.0, 0.0), FixStatus.ACCEPTED),  # as surprising, and where the held one says: confirmed
    ((0.0, 0.0, 0.0), FixStatus.UNCONFIRMED),  # at the prediction: it cannot tell the two apart
    ((0.0, 25.0, -20.0), FixStatus.HELD),  # refused by the gate: the held fix waits on
])
def test_a_surprising_fix_waits_for_the_next_to_agree(small_survey, rough_map, second, status):
    """A fix whose NIS is between the confirmation quantile and the gate is held; the next fix
    confirms it when it agrees with it and is as surprising to the prediction (both used), drops
    it when it agrees with the prediction, or, refused by the gate, leaves it held. ``second``:
    the next fix's offset from the truth, in the prediction's spreads north and in metres."""
    k1, k2 = 99, 109  # window ends (spacing 10)
    nav = _navigator_at(small_survey, rough_map, k1)
    _, cov = nav.predicted(k1)
    spread = float(np.sqrt(cov[0, 0] + 2.2))  # the prediction's and the fix's (as the graph grows it)
    nav.step(fix=_fix_at(small_survey, rough_map, k1, [2.9 * spread, 0.0]))
    held = nav.fixes[-1]
    assert 4.6 < held.nis < 13.8  # between the confirmation quantile and the gate
    assert held.status is FixStatus.HELD and "held" in held.detail
    while nav.index + 1 < k2:
        nav.step()
    nav.step(fix=_fix_at(small_survey, rough_map, k2, [second[0] * spread + second[1], second[2]]))
    first = next(f for f in nav.fixes if f.index == k1)
    assert first.status is status


def test_a_false_alarm_ends_when_a_fix_agrees_with_the_belief_held(small_survey, rough_map):
    """Two precise fixes 40 m off in a row (as a block of shifted pings gives) make the navigator
    lost with ``lost_windows=2``; the next genuine fix agrees with the belief it gave up, so the
    episode ends there, with no jump, and the track stays as good as the clean one."""
    config = CONFIG.replace(lost_windows=2)
    bad = {k: _fix_at(small_survey, rough_map, k, [40.0, -10.0]) for k in (99, 109)}
    nav = GraphNavigator(small_survey, rough_map, config)
    for k in range(small_survey.n_pings):
        nav.step(fix=bad.get(k))
    track = nav.track()
    clean = navigate_online(small_survey, rough_map, config)
    episodes = track.meta["lost_episodes"]
    assert len(episodes) == 1 and episodes[0]["declared"] == 109 and episodes[0]["end"] is not None
    assert any(f.detail == "the belief held" for f in track.fixes)
    truth = small_survey.true_pose[:, :2]
    rmse = {name: float(np.sqrt(np.mean(np.sum((t.pose[:, :2] - truth) ** 2, axis=1))))
            for name, t in (("clean", clean), ("spoiled", track))}
    assert rmse["spoiled"] <= 1.5 * rmse["clean"]


def test_two_fixes_agree_through_the_dead_reckoning_alone(small_survey, rough_map):
    """Agreement is judged on the DR from the first fix's prediction: the second's own
    prediction (moved by every fix used since, the first's among them) does not enter."""
    from tangraph.graph.lost import agreement
    from tangraph.graph.policy import Candidate

    k1, k2 = 99, 139
    nav = _navigator_at(small_survey, rough_map, k2)
    pose1, _ = nav.predicted_frame(k1)
    pose2, joint2 = nav.predicted_frame(k2)

    def candidate(k, pose, offset):
        fix = _fix_at(small_survey, rough_map, k, offset)
        return Candidate(k, int(fix.first), fix, np.asarray(pose, float), 0)

    first = candidate(k1, pose1, [0.0, 0.0])
    moved = pose2 + np.array([40.0, -30.0, 0.0])  # as if a fix had pulled the prediction
    assert agreement(nav, first, candidate(k2, moved, [0.0, 0.0]), joint2)
    assert agreement(nav, first, candidate(k2, pose2, [0.0, 0.0]), joint2)
    assert not agreement(nav, first, candidate(k2, pose2, [40.0, -30.0]), joint2)


def test_a_fix_whose_key_left_the_isam2_window_is_left_to_the_smoother(small_survey, rough_map):
    """A held or relocalising fix used late, after its key pose was marginalised, is not added
    to iSAM2 (GTSAM would refuse it): its record says so and the navigator goes on."""
    from tangraph.graph.lost import use
    from tangraph.graph.policy import Candidate

    config = CONFIG.replace(isam_window=3)
    nav = GraphNavigator(small_survey, rough_map, config)
    for _ in range(150):
        nav.step()
    assert not nav.isam.getLinearizationPoint().exists(0)
    key = 19
    fix = _fix_at(small_survey, rough_map, key, [0.0, 0.0])
    at = next(n for n, r in enumerate(nav.fixes) if r.index == key)
    use(nav, Candidate(key, int(fix.first), fix, small_survey.dr_pose[key], at), "late")
    assert nav.fixes[at].status is FixStatus.LEFT_WINDOW and "left iSAM2" in nav.fixes[at].detail
    nav.run()
    assert np.all(np.isfinite(nav.track().pose))


def test_without_confirmation_a_surprising_fix_is_used_at_once(small_survey, rough_map):
    """``confirm_probability=None``: a fix within the gate is used at once, however surprising."""
    config = CONFIG.replace(confirm_probability=None)
    k = 99
    nav = GraphNavigator(small_survey, rough_map, config)
    for _ in range(k):
        nav.step()
    _, cov = nav.predicted(k)
    spread = float(np.sqrt(cov[0, 0] + 2.2))
    nav.step(fix=_fix_at(small_survey, rough_map, k, [2.9 * spread, 0.0]))
    assert 4.6 < nav.fixes[-1].nis < 13.8 and nav.fixes[-1].status is FixStatus.ACCEPTED
