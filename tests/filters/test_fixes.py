"""The fixes made inside the filters (tangraph.filters.fixes): the windows and their schedule, a fix
laid with the calibration, and the decision on a fix (used, held, confirmed, dropped) with the
records it writes."""

from __future__ import annotations

import functools

import numpy as np
import pytest

from tangraph.filters import MLEConfig, TercomPFConfig, fixes, run_filter
from tangraph.filters.fixes import decide_fix, fix_due, fix_window
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.tercom_pf import tercom_pf_step
from tangraph.fix_records import FixStatus
from tests.filters.synthetic import gaussian_fix as _fix
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, seed=1, pings=30)
MODEL = navigation(SURVEY, initial_position_std=20.0, sounding_std=0.5)


def test_fix_windows_and_schedule():
    assert fix_window(MLEConfig(), SURVEY) == 5  # 30 beams per ping
    single = SURVEY.replace(
        beam_forward=SURVEY.beam_forward[:, :1],
        beam_starboard=SURVEY.beam_starboard[:, :1],
        beam_depth=SURVEY.beam_depth[:, :1],
    )
    assert fix_window(MLEConfig(), single) == 30  # about 30 soundings
    assert fix_window(MLEConfig(window=7), single) == 7
    assert [k for k in range(20) if fix_due(MLEConfig(fix_interval=3), k, 5)] == [4, 7, 10, 13, 16, 19]


def test_the_default_fix_window_is_computed_once_per_survey(monkeypatch):
    """A TERCOM-PF step without ``window`` asks fix_window at every ping: the survey's soundings
    are scanned the first time only."""
    survey = SURVEY.replace(meta={"copy": True})  # a survey not seen yet
    config = TercomPFConfig(n_particles=200)
    assert fix_window(config, survey) == 5

    def no_scan(*args, **kwargs):
        raise AssertionError("fix_window scanned the survey again")

    monkeypatch.setattr(fixes.np, "isfinite", no_scan)
    assert fix_window(config, survey) == 5
    monkeypatch.undo()
    step = functools.partial(tercom_pf_step, survey=survey, bathymetry=MAP)  # no window passed
    track = run_particle_filter(
        survey, MAP, config, step, method="tercom-pf", rng=np.random.default_rng(3), model=MODEL,
        count_keys=COUNTS,
    )  # fmt: skip
    reference = run_filter("tercom-pf", survey, MAP, config, model=MODEL, rng=np.random.default_rng(3))
    np.testing.assert_array_equal(track.pose, reference.pose)
    assert track.meta["n_fixes_accepted"] == reference.meta["n_fixes_accepted"] > 0


COUNTS = ("n_fixes_accepted", "n_fixes_rejected", "n_recentred")

DECIDE = MLEConfig()  # confirm_probability 0.9 (NIS 4.61), gate 13.8
STILL = (np.zeros(2), np.zeros((2, 2)))  # no displacement since the held fix
SEARCH = 30.0  # the search's half-width: a fix of std up to 5 m is precise (search_sigmas 3)


def _decide(fix, index, prediction, covariance, held, displacement, *, config=DECIDE, half_width=SEARCH):
    return decide_fix(fix, index, prediction, covariance, held, displacement, config, half_width=half_width)


def test_decide_fix_uses_a_fix_near_the_prediction_and_holds_a_surprising_one():
    prediction, covariance = np.zeros(2), np.eye(2)
    near = _decide(_fix([1.0, 1.0], 1.0), 9, prediction, covariance, None, None)
    assert (near.action, near.held, near.dropped) == ("use", None, None) and near.nis == pytest.approx(1.0)
    surprising = _decide(_fix([4.0, 0.0], 1.0), 9, prediction, covariance, None, None)
    assert surprising.action == "hold" and surprising.held.index == 9 and surprising.nis == pytest.approx(8.0)
    plain = _decide(_fix([40.0, 0.0], 1.0), 9, prediction, covariance, None, None,
                    config=MLEConfig(confirm_probability=None))
    assert plain.action == "use" and plain.held is None


def test_decide_fix_confirms_a_held_fix_by_a_second_that_agrees_through_the_dead_reckoning():
    held = _decide(_fix([10.0, 0.0], 1.0), 9, np.zeros(2), np.eye(2), None, None).held
    prediction = np.array([0.0, 8.0])  # the DR moved 8 m east since
    moved = (np.array([0.0, 8.0]), 0.5 * np.eye(2))
    # as surprising, and where the held fix has moved to: confirmed
    confirm = _decide(_fix([10.5, 8.0], 1.0), 14, prediction, np.eye(2), held, moved)
    assert (confirm.action, confirm.held, confirm.dropped) == ("confirm", None, None)
    # as surprising, but elsewhere: the held fix is dropped and the new one held
    other = _decide(_fix([-10.0, 8.0], 1.0), 14, prediction, np.eye(2), held, moved)
    assert other.action == "hold" and other.dropped is held and other.held.index == 14
    # at the prediction, far from the held fix: used, the held fix dropped
    refuted = _decide(_fix([0.0, 8.0], 1.0), 14, prediction, np.eye(2), held, moved)
    assert refuted.action == "use" and refuted.dropped is held and refuted.held is None
    # a vague fix agrees with both: used, the held fix waits one attempt more, then is dropped
    vague = _decide(_fix([5.0, 8.0], 6.0), 14, prediction, np.eye(2), held, moved)
    assert vague.action == "use" and vague.dropped is None and vague.held.attempts == 1
    again = _decide(_fix([5.0, 8.0], 6.0), 19, prediction, np.eye(2), vague.held, moved)
    assert again.action == "use" and again.held is None
    assert fixes.waited(held).attempts == 1 and fixes.waited(fixes.waited(held)) is None
    # as surprising and agreeing, but too vague for its search: nothing used, the held fix waits;
    # precise for a search twice as wide, the same fix confirms it
    loose = _decide(_fix([14.0, 8.0], 6.0), 14, prediction, np.eye(2), held, moved)
    assert loose.action == "wait" and loose.nis > 4.61 and loose.held.attempts == 1 and loose.dropped is None
    wide = _decide(_fix([14.0, 8.0], 6.0), 14, prediction, np.eye(2), held, moved, half_width=60.0)
    assert wide.action == "confirm"
    # the displacement's mean is the DR's: without it the two fixes would not agree
    assert _decide(_fix([10.5, 8.0], 1.0), 14, prediction, np.eye(2), held, STILL).action == "hold"


def test_a_filters_fix_is_laid_with_its_calibration_and_grown_by_what_is_uncertain_of_it():
    """SURVEY's DR has a 3 deg heading bias: windows laid with the raw DR are turned by it and
    their fixes miss the truth by 1-3 m, many stds; laid with the calibration that corrects it,
    within 0.7 m, and the covariance grows by the calibration's spread."""
    config, wide = MLEConfig(), np.eye(2) * 100.0
    known = (np.array([0.0, np.radians(3.0)]), np.zeros((2, 2)))
    unsure = (known[0], np.diag([0.02, np.radians(2.0)]) ** 2)
    for end in (9, 14, 19, 24):
        truth = SURVEY.true_pose[end, :2]
        fix = functools.partial(fixes.attempt_fix, SURVEY, MAP, end, truth, wide, config, 10, model=MODEL)
        (raw, _), (laid, record), (spread, _) = fix(), fix(calibration=known), fix(calibration=unsure)
        assert np.linalg.norm(raw.position - truth) > 1.0
        assert np.linalg.norm(laid.position - truth) < 0.7
        np.testing.assert_allclose(record.covariance, laid.covariance)
        assert np.all(np.linalg.eigvalsh(spread.covariance - laid.covariance) > 0.01)


def test_the_records_a_decision_writes():
    """A held fix's record is settled when its fate is: confirmed, dropped by a fix that does not
    agree, or out of attempts; a vague fix that agrees is recorded as such and the held one waits."""
    from tangraph.fix_records import FixRecord

    def record(index):
        return FixRecord.of(index, _fix([0.0, 0.0], 1.0), FixStatus.ACCEPTED, np.nan, SEARCH)

    prediction, moved = np.array([0.0, 8.0]), (np.array([0.0, 8.0]), 0.5 * np.eye(2))
    decision = _decide(_fix([10.0, 0.0], 1.0), 9, np.zeros(2), np.eye(2), None, None)
    (holding,), held = fixes.decided(record(9), decision, None)
    assert holding.status is FixStatus.HELD and held.record is holding and holding.nis == decision.nis
    confirm = _decide(_fix([10.5, 8.0], 1.0), 14, prediction, np.eye(2), held, moved)
    (settled, used), after = fixes.decided(record(14), confirm, held, "recentre")
    assert (settled.index, settled.status, after) == (9, FixStatus.CONFIRMED, None)
    assert used.accepted and used.detail == "confirms the fix at ping 9; recentre"
    refuted = _decide(_fix([0.0, 8.0], 1.0), 14, prediction, np.eye(2), held, moved)
    (dropped, used), _ = fixes.decided(record(14), refuted, held)
    assert dropped.status is FixStatus.UNCONFIRMED and "did not agree" in dropped.detail and used.accepted
    loose = _decide(_fix([14.0, 8.0], 6.0), 14, prediction, np.eye(2), held, moved)
    (vague,), waiting = fixes.decided(record(14), loose, held)
    assert vague.status is FixStatus.VAGUE and waiting.record is holding and waiting.attempts == 1
    assert fixes.expired(held, fixes.waited(held)) == ()
    (gone,) = fixes.expired(waiting, fixes.waited(waiting))
    assert gone.status is FixStatus.UNCONFIRMED and gone.detail == "no fix confirmed it in 2 attempts"
