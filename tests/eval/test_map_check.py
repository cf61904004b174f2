"""Check lines: a map's stated error tested against held-out soundings (tangraph.eval.map_check)."""

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.eval.map_check import MapCheck, check_map_error, window_scores
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.sensors.matern import matern_field
from tangraph.survey import Survey

AXIS_N = np.arange(0.0, 400.0, 2.0)
AXIS_E = np.arange(0.0, 2000.0, 2.0)
SOUNDING_STD = 0.1


def seafloor(north, east):
    return 30.0 + 0.02 * north + 1.5 * np.sin(east / 60.0) * np.cos(north / 45.0)


def line_survey(truth, rng, *, lines, offsets=(-3.0, 0.0, 3.0), name="s"):
    """Lines along east at the given norths, a ping per metre, beams across, soundings of the
    seafloor ``truth(north, east)`` with white noise; the reference track is the truth."""
    east = np.arange(20.0, 1980.0, 1.0)
    poses = np.concatenate([np.column_stack([np.full(east.size, n), east if i % 2 == 0 else east[::-1],
                                             np.full(east.size, 0.0 if i % 2 == 0 else np.pi / 2 * 2)])
                            for i, n in enumerate(lines)])
    k, b = poses.shape[0], len(offsets)
    fwd, stb = np.zeros((k, b)), np.tile(np.asarray(offsets, float), (k, 1))
    survey = Survey(time=np.arange(k, dtype=float), dr_pose=poses, true_pose=poses, vehicle_depth=np.zeros(k),
                    beam_forward=fwd, beam_starboard=stb, beam_depth=np.zeros((k, b)), meta={"name": name})
    north, east_ = survey.footprints(poses)
    depth = truth(north, east_) + SOUNDING_STD * rng.standard_normal((k, b))
    return survey.replace(beam_depth=depth)


def test_scores_are_standard_normal_when_the_map_errs_as_it_says():
    # the map is the seafloor less a Matérn field of the std and range it states: the window
    # means of held-out soundings, standardised, are N(0, 1) up to Monte Carlo error
    model = NavigationModel(sounding_std=SOUNDING_STD)
    scores = []
    for seed in range(6):
        rng = np.random.default_rng(seed)
        d = matern_field(AXIS_N, AXIS_E, 0.3, 20.0, rng=rng)
        grid = BathymetryMap(AXIS_N, AXIS_E, seafloor(AXIS_N[:, None], AXIS_E[None, :]) - d,
                             depth_std=np.full(d.shape, 0.3), correlation_length=20.0)
        truth = BathymetryMap(AXIS_N, AXIS_E, seafloor(AXIS_N[:, None], AXIS_E[None, :]))
        survey = line_survey(truth.depth_at, rng, lines=[100.0, 250.0])
        scores.append(window_scores(survey, grid, model, window=50.0))
    scores = np.concatenate(scores)
    # windows 50 m long, 2.5 ranges: nearly independent; RMS^2 of W normals has std sqrt(2 / W)
    assert scores.size > 400
    assert abs(np.mean(scores**2) - 1.0) < 4 * np.sqrt(2.0 / scores.size)
    assert np.mean(np.abs(scores) > 3.0) < 0.02


def test_a_patch_the_map_does_not_know_is_heavy_tailed():
    # the same, with the seafloor 2 m shallower over 400 m of one line: the bulk stays at 1,
    # the RMS and the share beyond 3 say a few windows are far worse than the map states
    model = NavigationModel(sounding_std=SOUNDING_STD)
    rng = np.random.default_rng(1)
    d = matern_field(AXIS_N, AXIS_E, 0.3, 20.0, rng=rng)
    grid = BathymetryMap(AXIS_N, AXIS_E, seafloor(AXIS_N[:, None], AXIS_E[None, :]) - d,
                         depth_std=np.full(d.shape, 0.3), correlation_length=20.0)
    truth = BathymetryMap(AXIS_N, AXIS_E, seafloor(AXIS_N[:, None], AXIS_E[None, :]))

    def changed(north, east):
        return truth.depth_at(north, east) - 2.0 * ((east > 800) & (east < 1200) & (north < 150))

    s = window_scores(line_survey(changed, rng, lines=[100.0, 250.0]), grid, model, window=50.0)
    check = MapCheck(s, np.zeros(s.size, int), ("changed",), 50.0)
    assert check.rms > 1.8
    assert 0.6 < check.robust < 1.4
    assert check.share_beyond_3 > 0.03


def test_check_map_error_holds_each_survey_out():
    rng = np.random.default_rng(2)
    surveys = [line_survey(seafloor, rng, lines=np.arange(10.0, 390.0, 6.0) + 2.0 * i, name=f"day {i}")
               for i in range(3)]
    calls = []
    check = check_map_error(surveys, cell=5.0, model=NavigationModel(sounding_std=SOUNDING_STD), window=100.0,
                            progress=lambda i, n: calls.append((i, n)))
    rows = check.per_survey()
    assert [r["survey"] for r in rows] == ["day 0", "day 1", "day 2"]
    assert calls == [(1, 3), (2, 3), (3, 3)]
    assert all(r["windows"] > 100 for r in rows)
    assert check.windows == sum(r["windows"] for r in rows)
    # dense lines of one seafloor: every held-out survey fits the others' map within a few sigma
    assert check.robust < 3.0
    assert "windows of 100 m" in check.summary()


def test_check_map_error_refuses_bad_input():
    rng = np.random.default_rng(3)
    one = line_survey(seafloor, rng, lines=[50.0])
    with pytest.raises(TangraphError, match="at least two surveys"):
        check_map_error([one], cell=5.0)
    with pytest.raises(TangraphError, match="window must be > 0"):
        check_map_error([one, one], cell=5.0, window=0.0)
    with pytest.raises(TangraphError, match="no reference track"):
        check_map_error([one, one.replace(true_pose=None, meta={"name": "dr only"})], cell=5.0)


def test_calibrate_error_scales_the_map_error_by_the_check():
    from tangraph.eval.map_check import calibrate_error
    from tangraph.gridding_surveys import grid_surveys

    rng = np.random.default_rng(4)
    surveys = [line_survey(seafloor, rng, lines=np.arange(10.0, 390.0, 6.0) + 2.0 * i) for i in range(2)]
    grid = grid_surveys(surveys, cell=5.0)
    scores = np.array([3.0, -3.0] * 10)
    scaled = calibrate_error(grid, MapCheck(scores, np.zeros(20, int), ("a",), 50.0))
    assert scaled.error_scale == pytest.approx(3.0)
    np.testing.assert_allclose(scaled.depth.depth_std, 3.0 * grid.depth.depth_std)
    assert scaled.meta["check_lines"]["rms"] == pytest.approx(3.0)
    # a map is never made better than its gridding says
    calm = calibrate_error(grid, MapCheck(scores / 10, np.zeros(20, int), ("a",), 50.0))
    np.testing.assert_array_equal(calm.depth.depth_std, grid.depth.depth_std)
    with pytest.raises(TangraphError, match="scored 3 windows"):
        calibrate_error(grid, MapCheck(scores[:3], np.zeros(3, int), ("a",), 50.0))


def test_one_survey_is_checked_line_by_line():
    # one survey of 20 lines: split at its turns (here jumps between lines), each line held out
    # against the map of the other 19
    from tangraph.eval.map_check import survey_lines

    rng = np.random.default_rng(6)
    survey = line_survey(seafloor, rng, lines=np.arange(100.0, 140.0, 2.0), name="one")
    lines = survey_lines(survey)
    assert len(lines) == 20
    assert [line.meta["line"] for line in lines] == list(range(20))
    assert all(np.ptp(line.true_pose[:, 0]) == 0 for line in lines)  # each one line of constant north
    check = check_map_error([survey], cell=5.0, model=NavigationModel(sounding_std=SOUNDING_STD),
                            window=100.0, lines=True)
    assert check.names[0] == "one line 0" and len(check.names) == 20
    assert check.windows > 200
    assert check.robust < 3.0
    with pytest.raises(TangraphError, match="at least two lines"):
        check_map_error([survey.pings(0, 100)], cell=5.0, lines=True)
