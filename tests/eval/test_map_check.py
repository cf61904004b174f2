"""Check lines: a map's stated error tested against held-out soundings (tangraph.eval.map_check):
each survey, or each line of one survey, against the map of the others, and the map's error
scaled by the check."""

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.eval.map_check import MapCheck, check_map_error
from tangraph.sensors import NavigationModel
from tests.eval.line_cases import SOUNDING_STD, line_survey, seafloor


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
    two = line_survey(seafloor, rng, lines=[70.0], name="t")  # 20 m beside it: they never cross
    with pytest.raises(TangraphError, match="no reference track"):
        check_map_error([one, two.replace(true_pose=None, meta={"name": "dr only"})], cell=5.0)
    with pytest.raises(TangraphError, match="check_map_error: s and s again hold the same 1960 pings"):
        check_map_error([one, one.replace(meta={"name": "s again"})], cell=5.0)
    with pytest.raises(TangraphError, match="no window of 50 m of a held-out survey lies on the map of the "
                                            "others .*: surveys that overlap, or a shorter window"):
        check_map_error([one, two], cell=5.0)


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


@pytest.mark.parametrize("dof", [1.5, 4.0])
def test_the_tail_of_the_scores_is_fitted_by_its_degrees_of_freedom(dof):
    """Scores of a Student-t: its degrees of freedom recovered within four of their standard
    errors (the Fisher information of ``nu`` with the scale known, from 4000 scores)."""
    from scipy import special

    scores = np.random.default_rng(7).standard_t(dof, 4000)
    check = MapCheck(scores, np.zeros(scores.size, int), ("t",), 50.0)
    v = dof
    info = 0.25 * (special.polygamma(1, v / 2) - special.polygamma(1, (v + 1) / 2)) - (v + 5) / (
        2 * v * (v + 1) * (v + 3))
    assert abs(check.misfit_dof - dof) < 4 / np.sqrt(scores.size * info)
    gaussian = MapCheck(np.random.default_rng(8).standard_normal(4000), np.zeros(4000, int), ("n",), 50.0)
    assert gaussian.misfit_dof > 30
    assert np.isnan(MapCheck(np.zeros(0), np.zeros(0, int), (), 50.0).misfit_dof)


def test_the_tail_is_the_maximum_likelihood_student_t_with_its_scale():
    """Scores of a Student-t of scale 2: the fit is scipy's maximum-likelihood one (the slow
    reference), its scale never below 1, and a Gaussian's tail is none (its scale the RMS)."""
    from scipy import stats

    scores = 2.0 * np.random.default_rng(9).standard_t(2.5, 3000)
    scale, dof = MapCheck(scores, np.zeros(scores.size, int), ("t",), 50.0).tail()
    ref_dof, _, ref_scale = stats.t.fit(scores, floc=0.0)
    assert scale == pytest.approx(ref_scale, rel=2e-3) and dof == pytest.approx(ref_dof, rel=5e-3)
    narrow = MapCheck(scores / 4, np.zeros(scores.size, int), ("t",), 50.0)
    assert narrow.tail() == (1.0, pytest.approx(narrow.misfit_dof))
    normal = np.random.default_rng(10).standard_normal(3000) * 1.5
    gaussian = MapCheck(normal, np.zeros(normal.size, int), ("n",), 50.0)
    assert gaussian.tail()[1] > 30
    assert np.isnan(MapCheck(normal[:0], np.zeros(0, int), (), 50.0).tail()).all()


def test_calibrate_error_gives_the_map_the_tail_its_check_lines_found():
    from tangraph.eval.map_check import calibrate_error
    from tangraph.gridding_surveys import grid_surveys

    rng = np.random.default_rng(4)
    surveys = [line_survey(seafloor, rng, lines=np.arange(10.0, 390.0, 6.0) + 2.0 * i) for i in range(2)]
    grid = grid_surveys(surveys, cell=5.0)
    scores = 1.5 * np.random.default_rng(11).standard_t(1.5, 500)
    check = MapCheck(scores, np.zeros(scores.size, int), ("a",), 50.0)
    heavy = calibrate_error(grid, check)
    scale, dof = check.tail()
    assert heavy.error_scale == scale < check.rms and heavy.error_dof == dof < 3
    assert heavy.depth.error_dof == dof
    np.testing.assert_allclose(heavy.depth.depth_std, scale * grid.depth.depth_std)
    assert heavy.meta["check_lines"]["misfit_dof"] == pytest.approx(dof, abs=1e-4)
    plain = calibrate_error(grid, MapCheck(3.0 * rng.standard_normal(500), np.zeros(500, int), ("a",), 50.0))
    assert plain.error_dof is None and plain.depth.error_dof is None


def planted_windows(walk: float, rng, surveys: int = 6, windows: int = 60, spacing: float = 60.0,
                    time_constant: float = np.inf):
    """Check-line windows whose mean residuals are a map error of stated variance 0.01 m^2 at a
    scale of 1.3 (1 % of them a patch ten times worse) plus a drift: a random walk of ``walk``
    m/sqrt(s), or with a finite ``time_constant`` (s) the Gauss-Markov offset of that initial
    walk (std ``walk sqrt(time_constant / 2)``)."""
    time = np.tile(np.arange(windows) * spacing, surveys)
    owner = np.repeat(np.arange(surveys), windows)
    variance = np.full(time.size, 0.01)
    worse = np.where(rng.random(time.size) < 0.01, 10.0, 1.0)
    error = 1.3 * 0.1 * rng.standard_normal(time.size) * worse
    phi = np.exp(-spacing / time_constant)
    step = walk * np.sqrt(spacing if np.isinf(time_constant) else (1 - phi**2) * time_constant / 2.0)
    drift = []
    for _ in range(surveys):
        d = np.empty(windows)
        d[0] = 0.0 if np.isinf(time_constant) else walk * np.sqrt(time_constant / 2.0) * rng.standard_normal()
        for k in range(1, windows):
            d[k] = phi * d[k - 1] + step * rng.standard_normal()
        drift.append(d)
    mean = error + np.concatenate(drift)
    return MapCheck(mean / np.sqrt(variance), owner, tuple(f"s{i}" for i in range(surveys)), 50.0, time,
                    mean, variance)


@pytest.mark.parametrize("walk", [0.0, 0.005, 0.02])
def test_the_check_lines_measure_how_fast_the_tide_drifts(walk):
    checks = [planted_windows(walk, np.random.default_rng(seed)) for seed in range(20)]
    estimates = np.array([check.drift()["walk"] for check in checks])
    # over 20 independent checks: centred on the planted walk (none: a few mm per sqrt(s))
    assert abs(np.median(estimates) - walk) < 0.2 * walk + 0.003
    assert np.all(estimates >= 0.0)


def test_the_check_lines_measure_a_drift_that_forgets():
    checks = [planted_windows(0.02, np.random.default_rng(seed), time_constant=300.0) for seed in range(20)]
    fits = [check.drift() for check in checks]
    walk, std, time = (np.median([f[k] for f in fits]) for k in ("walk", "std", "time"))
    assert walk == pytest.approx(0.02, rel=0.2)
    assert std == pytest.approx(0.02 * np.sqrt(150.0), rel=0.2)
    assert time == pytest.approx(300.0, rel=0.35)
    assert np.median([f["scale"] for f in fits]) == pytest.approx(1.3, rel=0.3)


def test_a_check_without_its_windows_times_has_no_drift():
    check = MapCheck(np.zeros(3), np.zeros(3, int), ("a",), 50.0)
    assert all(np.isnan(v) for v in check.drift().values())


def test_the_drifts_f_test_tells_a_drift_from_none():
    """Over 20 independent checks each: no drift is never stated at the 1 % level, a drift the
    size of Lake Caputh's (0.02 m/sqrt(s) at first, forgotten over 300 s) always."""
    none = [planted_windows(0.0, np.random.default_rng(seed)).drift()["p_value"] for seed in range(20)]
    drifting = [planted_windows(0.02, np.random.default_rng(seed), time_constant=300.0).drift()["p_value"]
                for seed in range(20)]
    assert min(none) > 0.01 and max(drifting) < 0.01


def test_calibrate_error_gives_the_map_the_drift_its_check_lines_found():
    from tangraph.eval.map_check import DRIFT_P_VALUE, calibrate_error
    from tangraph.gridding_surveys import grid_surveys

    rng = np.random.default_rng(4)
    surveys = [line_survey(seafloor, rng, lines=np.arange(10.0, 390.0, 6.0) + 2.0 * i) for i in range(2)]
    grid = grid_surveys(surveys, cell=5.0)
    check = planted_windows(0.02, np.random.default_rng(3), time_constant=300.0)
    drift = check.drift()
    assert drift["p_value"] < DRIFT_P_VALUE
    drifting = calibrate_error(grid, check)
    assert drifting.error_drift == (drift["std"], drift["time"]) == drifting.depth.error_drift
    assert drifting.meta["check_lines"]["drift_p_value"] == pytest.approx(drift["p_value"], abs=1e-6)
    steady = calibrate_error(grid, planted_windows(0.0, np.random.default_rng(3)))
    assert steady.error_drift is None and steady.depth.error_drift is None


def test_each_sounding_is_scored_in_a_cell_with_data_or_a_filled_gap():
    from tangraph.eval.map_check import cell_scores, cells_summary
    from tangraph.gridding_surveys import grid_surveys

    rng = np.random.default_rng(5)
    model = NavigationModel(sounding_std=SOUNDING_STD)
    prior = line_survey(seafloor, rng, lines=np.arange(20.0, 380.0, 20.0))
    grid = grid_surveys([prior], cell=5.0, fill=3)
    on = line_survey(seafloor, rng, lines=[100.0, 200.0], offsets=(0.0,))  # on the gridded lines
    between = line_survey(seafloor, rng, lines=[110.0, 210.0], offsets=(0.0,))  # midway: filled cells
    r_on, s_on, measured_on = cell_scores(on, grid, model)
    r_between, s_between, measured_between = cell_scores(between, grid, model)
    assert measured_on.all() and not measured_between.any()
    assert r_on.size == measured_on.size > 3000 and np.median(r_on) == pytest.approx(0.0, abs=1e-12)
    assert np.all(s_on >= SOUNDING_STD) and np.median(s_between) > np.median(s_on)
    summary = cells_summary(np.r_[r_on, r_between], np.r_[s_on, s_between],
                            np.r_[measured_on, measured_between])
    assert summary["data_cells"]["soundings"] == r_on.size
    assert summary["filled_cells"]["soundings"] == r_between.size
    z = r_on / s_on
    spread = 1.4826 * np.median(np.abs(z - np.median(z)))
    assert summary["data_cells"]["robust_z"] == pytest.approx(spread, abs=1e-3)
    # the map's cells with data err as stated (the sounding noise and the cells' own error)
    assert 0.7 < summary["data_cells"]["robust_z"] < 1.3
    # held out in turn, every sounding on the map is scored in one kind of cell or the other
    check = check_map_error([prior, on, between], cell=5.0, fill=3, model=model, window=100.0)
    kinds = check.by_cell()
    assert set(kinds) == {"data_cells", "filled_cells"}
    assert check.cells is not None and sum(v["soundings"] for v in kinds.values()) == check.cells[0].size
    with pytest.raises(TangraphError, match="no reference track"):
        cell_scores(on.replace(true_pose=None), grid, model)
