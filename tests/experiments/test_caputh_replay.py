"""The Lake Caputh study's own arithmetic: the spoiled DR and the calibration the GPS implies."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.experiments.registry import load_experiment
from tangraph.survey import Survey


def _survey() -> Survey:
    t = np.arange(200.0)
    track = np.column_stack([100 * np.sin(t / 30.0), 2.0 * t, np.full_like(t, 0.3)])
    zeros = np.zeros((t.size, 1))
    return Survey(time=t, dr_pose=track, vehicle_depth=t * 0, beam_forward=zeros, beam_starboard=zeros,
                  beam_depth=zeros + 5.0, true_pose=track.copy())


def test_the_gps_implies_the_constant_errors_added_to_a_dr():
    study = load_experiment("caputh_replay")
    survey = _survey()
    assert study.gps_calibration(survey) == pytest.approx((0.0, 0.0), abs=1e-12)
    spoiled = study.spoil(survey, 3.0, 0.03)
    k, b = study.gps_calibration(spoiled)
    assert (k, np.degrees(b)) == pytest.approx((0.03, 3.0), abs=1e-9)
    np.testing.assert_allclose(spoiled.dr_pose[:, 2], survey.dr_pose[:, 2] + np.radians(3.0))
    assert spoiled.dr_pose[0, :2] == pytest.approx(survey.dr_pose[0, :2])  # turned about the start


def test_the_study_refuses_a_folder_without_the_data(tmp_path, capsys):
    study = load_experiment("caputh_replay")
    with pytest.raises(SystemExit):
        study.main(["--data", str(tmp_path), "--out", str(tmp_path / "out")])
    assert "holds no Lake Caputh data" in capsys.readouterr().err


def test_scores_count_the_poses_confidently_wrong_that_were_not_flagged_lost():
    from tangraph.track import Track

    study = load_experiment("caputh_replay")
    survey = _survey()
    pose = survey.true_pose.copy()
    pose[100:, 0] += 10.0  # half the track 10 m off, with a std of 1 m (and the GPS's 1.5 m)
    track = Track(time=survey.time, pose=pose, covariance=np.tile(np.eye(3), (200, 1, 1)))
    assert study.scores(track, survey, 1.5)["confident_wrong"] == pytest.approx(0.5)
    flagged = Track(time=survey.time, pose=pose, covariance=track.covariance,
                    meta={"lost_steps": list(range(150, 200))})
    assert study.scores(flagged, survey, 1.5)["confident_wrong"] == pytest.approx(0.25)
    assert study.scores(track, survey, 10.0)["confident_wrong"] == 0.0  # within the GPS's error


def test_the_map_error_goals_are_checked_on_the_long_runs_with_spoiled_and_compass_drs():
    study = load_experiment("caputh_replay")
    row = {"run": "r", "method": "pf", "duration_min": 97.0, "median": 14.0, "dr_median": 73.0,
           "anees": 4.0, "confident_wrong": 0.02}
    lines = study.map_error_goals([{**row, "case": "compass"}, {**row, "case": "boat"},
                                   {**row, "case": "compass", "duration_min": 7.0}])
    assert lines == ["- r compass pf: median 14.00 m (met, <= 36.50 m); ANEES 4.00 (missed, <= 3.00); "
                     "confidently wrong 2.00 % (met, <= 5.00 %)"]


@pytest.mark.parametrize("name", ["config.toml", "config_turn_walk.toml", "config_check_lines.toml",
                                  "config_tracking.toml", "config_front_end.toml", "config_field.toml",
                                  "config_field_offset.toml", "config_map_drift.toml",
                                  "config_acquired.toml"])
def test_every_configuration_gives_models_the_graph_accepts(name):
    from tangraph.graph.fixes import check_tide_drift

    study = load_experiment("caputh_replay")
    cfg = study.load_config(study.HERE / name)
    for source in ("boat", "compass"):
        model, graph = study.estimator(cfg, source, "smoother")
        assert check_tide_drift(graph, model) is model
    if name == "config.toml":  # the map's check lines measured the drift it states
        assert model.tide_drift_std == 0.2 and model.tide_drift_time == 170.0
        line = study._drift_line({"drift_std": 0.196, "drift_time": 172.0, "drift_scale": 0.0}, cfg)[0]
        assert "drift by 0.196 m over 172 s" in line and "compass: 0.2 m over 170 s" in line
