"""TAP fixes (tangraph.matching.tap, with its regions in tap_regions and its noise model in
tap_noise): known answers, regions' nesting, covariance against the CRLB, the jackknife, the map
error's sandwich, flags and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap, ridges
from tangraph.matching.patch import MatchingError
from tangraph.matching.tap import RegionMethod, TapConfig, criterion_at, nees, tap_fix
from tangraph.survey import footprints
from tests.matching.tap_cases import CELL, rough_map, survey_on


def bowl(a=2e-4, b=1e-4, c=5e-5):
    """A paraboloid seabed: its gradient is linear in position, so with the tide removed the
    residuals are exactly linear in the shift and the curvature covariance is the CRLB."""
    north = np.arange(0, 1500.0, CELL)
    east = np.arange(0, 1500.0, CELL)
    nn, ee = np.meshgrid(north - 700, east - 800, indexing="ij")
    return BathymetryMap(north=north, east=east, depth=100 + a * nn**2 + b * ee**2 + c * nn * ee, name="bowl")


def test_noise_free_fix_lands_on_the_truth_with_the_tide():
    m = rough_map()
    s = survey_on(m)
    fix = tap_fix(s, m, end=9, n_pings=10, config=TapConfig(half_width=40.0))
    np.testing.assert_allclose(fix.position, s.true_pose[9, :2], atol=1e-6)
    assert fix.tide == pytest.approx(1.5, abs=1e-9)  # measured = map + tide: one sign everywhere
    assert fix.sigma == pytest.approx(0.0, abs=1e-6)
    assert fix.n_soundings == 410


def test_a_noise_free_window_on_a_map_with_an_error_is_a_fix_not_a_crash():
    """Soundings that fit the map exactly leave no scatter: with a map error in the model the
    fix is still made (at the truth), its shared map error dominating its covariance."""
    from tangraph.sensors import NavigationModel
    from tangraph.sensors.terrain import survey_map_error

    m = rough_map()
    s = survey_on(m)
    model = NavigationModel(map_std=0.3, map_correlation_length=50.0)
    shared, error = survey_map_error(s, m, model)
    fix = tap_fix(s, m, end=9, n_pings=10, config=TapConfig(half_width=40.0), shared=shared, error=error)
    np.testing.assert_allclose(fix.position, s.true_pose[9, :2], atol=1e-6)
    assert np.all(np.isfinite(fix.covariance))
    assert np.linalg.eigvalsh(fix.covariance).min() > 1e-6  # the shared map error, not the zero scatter


def test_a_search_centre_that_is_not_a_position_is_a_matching_error():
    m = rough_map()
    s = survey_on(m)
    with pytest.raises(MatchingError, match=r"centre must be a finite \(north, east\), got \[nan, 400.0\]"):
        tap_fix(s, m, end=9, n_pings=10, prior=[np.nan, 400.0])


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_noisy_fix_recovers_the_truth_and_regions_nest(seed):
    m = rough_map(seed)
    s = survey_on(m, noise=0.3, seed=seed)
    fix = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0, step=2.5))
    assert np.hypot(*(fix.position - s.true_pose[9, :2])) < 2 * CELL
    assert fix.sigma == pytest.approx(0.3, rel=0.25)
    xie, wang = fix.regions[RegionMethod.XIE], fix.regions[RegionMethod.WANG]
    assert np.all(wang.mask[xie.mask])  # Xie inside Wang
    assert wang.area >= xie.area > 0
    assert fix.accepted, fix.quality.reasons


def test_curvature_covariance_equals_the_crlb_on_a_paraboloid():
    m = bowl()
    s = survey_on(m, noise=0.2, seed=4, start=(600.0, 700.0))
    fix = tap_fix(s, m, 9, 10, TapConfig(half_width=30.0, calibrate=False))
    np.testing.assert_allclose(fix.covariances["curvature"], fix.covariances["crlb"], rtol=0.05)


def test_the_truth_is_inside_the_calibrated_region_and_nees_is_finite():
    m = rough_map(5)
    s = survey_on(m, noise=0.3, seed=5)
    fix = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0))
    patch_truth = s.true_pose[9, :2]
    from tangraph.matching.patch import window_patch

    q_truth = criterion_at(m, window_patch(s, 9, 10), patch_truth)[0]
    assert q_truth <= fix.regions[RegionMethod.CALIBRATED].threshold
    assert np.isfinite(nees(fix.position - patch_truth, fix.covariance))


def test_flat_terrain_is_flagged_uninformative_with_a_large_covariance():
    north = east = np.arange(0, 1500.0, CELL)
    flat = BathymetryMap(
        north=north, east=east, depth=80 + 1e-3 * np.random.default_rng(0).normal(size=(300, 300))
    )
    s = survey_on(flat, noise=0.3)
    fix = tap_fix(s, flat, 9, 10, TapConfig(half_width=40.0))
    assert not fix.quality.informative and not fix.accepted
    assert np.sqrt(np.linalg.eigvalsh(fix.covariance).max()) > 15.0  # of the order of the search box


def test_periodic_ridges_are_flagged_multimodal():
    m = ridges((300, 300), CELL, rng=np.random.default_rng(0), spacing=30.0, height=4.0, orientation=0.0)
    s = survey_on(m, noise=0.1, heading=0.0, start=(500.0, 700.0))  # running along the ridges
    fix = tap_fix(s, m, 9, 10, TapConfig(half_width=60.0))
    assert fix.quality.multimodal or not fix.quality.informative
    assert not fix.accepted


def test_bad_input_is_refused_with_a_reason():
    m = rough_map()
    s = survey_on(m)
    with pytest.raises(TangraphError, match="alpha must lie in"):
        TapConfig(alpha=1.5)
    with pytest.raises(MatchingError, match="starts before the survey"):
        tap_fix(s, m, 3, 10)
    with pytest.raises(MatchingError, match="fewer than min_soundings"):
        tap_fix(s.replace(beam_depth=np.where(np.arange(41) < 1, s.beam_depth, np.nan)), m, 9, 5)
    nowhere = r"no candidate within 50.0 m of \[-500.0, 0.0\] has every sounding"
    with pytest.raises(MatchingError, match=nowhere):
        tap_fix(s, m, 9, 10, prior=(-500.0, 0.0))


def test_calibrated_region_covers_the_truth_at_its_level():
    """300 seeded fixes on one rough terrain: the calibrated 95 % region holds the truth in
    0.95 +- 4 binomial standard errors of the fixes, and the region covariance is never
    over-confident (mean NEES below 2 + 4 standard errors) and at most mildly conservative (mean
    NEES above 1: here the likelihood is narrower than the 2.5 m grid, the covariance is the
    Cramér-Rao bound at the fix, and bilinear terrain is sharper than its gradients say)."""
    from tangraph.matching.patch import window_patch

    m = rough_map(11)
    runs = 300
    inside, nees_values = [], []
    for seed in range(runs):
        s = survey_on(m, noise=0.3, seed=100 + seed, pings=8, beams=21)
        patch = window_patch(s, 7, 8)
        truth = s.true_pose[7, :2]
        fix = tap_fix(s, m, 7, 8, TapConfig(half_width=25.0, step=2.5))
        q_truth = criterion_at(m, patch, truth)[0]
        inside.append(q_truth <= fix.regions[RegionMethod.CALIBRATED].threshold)
        nees_values.append(nees(fix.position - truth, fix.covariances["region"]))
    coverage = np.mean(inside)
    assert abs(coverage - 0.95) < 4 * np.sqrt(0.95 * 0.05 / runs), coverage
    assert 1.0 < np.mean(nees_values) < 2.0 + 4 * 2.0 / np.sqrt(runs), np.mean(nees_values)


def test_a_clean_window_keeps_its_region_covariance_under_the_jackknife():
    m = rough_map(2)
    s = survey_on(m, noise=0.3, seed=2)
    with_jack = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0, step=2.5))
    plain = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0, step=2.5, jackknife=False))
    np.testing.assert_allclose(with_jack.position, plain.position)
    assert "jackknife" in with_jack.covariances
    # every ping carries a tenth of the information: leaving one out moves the fix little
    grown = np.linalg.eigvalsh(np.linalg.solve(plain.covariance, with_jack.covariance)).max()
    assert 1.0 - 1e-9 <= grown < 4.0


def test_a_fix_that_rests_on_one_ping_gets_the_jackknifes_large_covariance():
    """A flat seabed with one mound under one ping's swath only: the fix holds only while that
    ping is in the window, so the jackknife over pings says it is not known."""
    north = east = np.arange(0, 1500.0, CELL)
    nn, ee = np.meshgrid(north - 520.0, east - 460.0, indexing="ij")  # under ping 3 (pings 20 m apart)
    m = BathymetryMap(north=north, east=east, depth=80.0 - 4.0 * np.exp(-(nn**2 + ee**2) / (2 * 4.0**2)))
    s = survey_on(m, noise=0.05, seed=3, spacing=20.0)
    plain = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0, jackknife=False))
    fix = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0))
    assert np.sqrt(np.linalg.eigvalsh(plain.covariance).max()) < 3.0  # the mound pins it down...
    assert np.sqrt(np.linalg.eigvalsh(fix.covariance).max()) > 10.0  # ...but one ping sees it


def test_a_best_match_on_the_search_edge_says_the_truth_may_lie_beyond():
    m = rough_map(4)
    s = survey_on(m, noise=0.1, seed=4, offset=(0.0, 0.0))
    prior = s.true_pose[9, :2] + np.array([55.0, 0.0])  # the truth is 55 m away, the search 40 m
    fix = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0), prior=prior)
    assert fix.quality.outside and not fix.accepted
    inside = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0), prior=s.true_pose[9, :2] + 10.0)
    assert not inside.quality.outside


def test_the_fix_says_whether_its_region_holds_the_prediction():
    """The search is centred on the prediction: a region far from it leaves it out; a window
    that tells nothing (a flat seabed) holds it wherever its best match lies."""
    m = rough_map(4)
    s = survey_on(m, noise=0.1, seed=4, offset=(0.0, 0.0))
    far = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0), prior=s.true_pose[9, :2] + np.array([55.0, 0.0]))
    assert far.quality.outside and not far.quality.holds_centre
    near = tap_fix(s, m, 9, 10, TapConfig(half_width=40.0), prior=s.true_pose[9, :2])
    assert near.quality.holds_centre
    flat = BathymetryMap(north=m.north, east=m.east, depth=np.full(m.depth.shape, 80.0))
    plain = survey_on(flat, noise=0.1, seed=4, offset=(0.0, 0.0))
    vague = tap_fix(plain, flat, 9, 10, TapConfig(half_width=40.0), prior=plain.true_pose[9, :2] + 20.0)
    assert not vague.quality.informative and vague.quality.holds_centre


def _inflation_reference(m, s, fix, error) -> float:
    """The window's own map error's sandwich ratio by the dense double sum over its soundings."""
    from tangraph.sensors import matern_correlation

    north, east = footprints(s.true_pose[:10] + np.append(fix.position - s.true_pose[9, :2], 0.0),
                             s.beam_forward[:10], s.beam_starboard[:10])
    north, east = north.ravel(), east.ravel()
    g = m.gradient_at(north, east)
    g = g - g.mean(axis=0)
    distance = np.hypot(north[:, None] - north[None], east[:, None] - east[None])
    shared = np.zeros((2, 2))
    for part in error.components():
        w = part.std_at(north, east)[:, None] * g
        correlation = matern_correlation(distance, part.correlation_length)
        np.fill_diagonal(correlation, 0.0)
        shared += w.T @ correlation @ w
    s2 = fix.sigma**2 * north.size / (north.size - 3)
    return 1.0 + np.trace(np.linalg.solve(g.T @ g, shared)) / (2.0 * s2)


def test_a_windows_own_map_error_widens_its_likelihood_by_the_exact_sandwich():
    """The fix's variance inflation from the map error its soundings share is the dense
    sandwich on the map gradients (soundings whose gradients differ in sign cancel), not the
    row-sum bound's; with it the fix holds the truth over seafloors that are the map plus a
    drawn error field: the mean NEES of 200 independent draws is 2 (chi-square(2)) within 3.5
    Monte Carlo standard errors, 2 +- 3.5 sqrt(2 * 2 / 200) = 1.50-2.50. Measured over 1000
    draws: mean 1.90 +- 0.08, consistent; one draw's sd is 2.5 against chi-square's 2 (heavier
    tails), hence 3.5 rather than 3 standard errors (2.8 of the measured ones); 200-draw block
    means 1.74-2.04. The row-sum bound's inflation made the mean 0.34."""
    from tangraph.sensors import NavigationModel, matern_field
    from tangraph.sensors.terrain import map_error

    m = rough_map(3)
    model = NavigationModel(map_std=0.3, map_correlation_length=30.0)
    error = map_error(m, model)
    config = TapConfig(half_width=40.0, jackknife=False)
    nees_values = []
    runs = 200
    for seed in range(runs):
        field = matern_field(m.north, m.east, 0.3, 30.0, rng=np.random.default_rng(100 + seed))
        seafloor = m.replace(depth=m.depth + field)
        s = survey_on(seafloor, noise=0.05, seed=seed)
        fix = tap_fix(s, m, end=9, n_pings=10, config=config, error=error)
        if seed == 0:  # the residuals' own inflation left out: the map error's alone
            alone = tap_fix(s, m, end=9, n_pings=10, config=TapConfig(half_width=40.0, calibrate=False),
                            error=error)
            reference = _inflation_reference(m, s, alone, error)
            assert alone.variance_inflation == pytest.approx(reference, rel=0.03)
        nees_values.append(nees(fix.position - s.true_pose[9, :2], fix.covariance))
    assert abs(np.mean(nees_values) - 2.0) < 3.5 * np.sqrt(2 * 2 / runs), np.mean(nees_values)


def test_the_tides_drift_within_a_window_widens_its_fix_by_the_exact_sandwich():
    """The covariance the tide's drift adds to a least-squares fix is ``I^-1 H^T C H I^-1``: the
    Monte Carlo covariance of the fix of drift-only residuals (4000 draws: a variance's relative
    standard error of 2.2 %, so within 12 % on every entry's scale)."""
    import types

    from tangraph.matching.patch import _drift_covariance
    from tangraph.matching.tap_noise import _drift_sandwich

    rng = np.random.default_rng(4)
    pings, beams = 30, 6
    ping = np.repeat(np.arange(pings), beams) + 100
    trend = np.column_stack([np.linspace(-1, 1, ping.size), np.zeros(ping.size)])
    g = rng.normal(size=(ping.size, 2)) + trend
    drift = _drift_covariance(np.arange(pings) * 2.0, 0.3, 20.0)
    patch = types.SimpleNamespace(ping=ping, first=100, drift=drift)
    added, white = _drift_sandwich(g, 0.01, patch)
    centred = g - g.mean(axis=0)
    solve = np.linalg.solve(centred.T @ centred, centred.T)
    draws = rng.multivariate_normal(np.zeros(pings), drift, size=4000)[:, ping - 100]  # one per ping
    fixes = draws @ solve.T
    np.testing.assert_allclose(np.cov(fixes.T), added, atol=0.12 * np.abs(added).max())
    assert np.allclose(white, 0.01 * np.linalg.inv(centred.T @ centred))


def test_a_fix_with_the_tides_drift_in_its_model_holds_the_truth():
    """Windows of 20 pings on a bowl whose depths drift by 0.1 m over 20 s. The drift's exact
    sandwich (the least-squares fix's covariance with it, ``covariances["map"]``) holds the fix's
    error: the mean NEES of 200 independent windows is 2 within 3.5 Monte Carlo standard errors
    (1.50-2.50; measured 1.77). The fix's covariance is at least that (the residuals' own
    inflation, which sees the drift too, may widen it further: mean NEES 1.06 here), where a fix
    that takes the tide as constant over the window claims a tenth of its error (18)."""
    from tangraph.matching.patch import _drift_covariance

    m = bowl()
    config = TapConfig(half_width=40.0, jackknife=False)
    runs, pings = 200, 20
    chol = np.linalg.cholesky(_drift_covariance(np.arange(pings, dtype=float), 0.1, 20.0))
    exact, final, without = [], [], []
    for seed in range(runs):
        s = survey_on(m, noise=0.05, seed=seed, pings=pings, start=(600.0, 650.0), spacing=4.0)
        shift = chol @ np.random.default_rng(1000 + seed).normal(size=pings)
        s = s.replace(beam_depth=s.beam_depth + shift[:, None])
        truth = s.true_pose[pings - 1, :2]
        fix = tap_fix(s, m, end=pings - 1, n_pings=pings, config=config, drift=(0.1, 20.0))
        exact.append(nees(fix.position - truth, fix.covariances["map"]))
        final.append(nees(fix.position - truth, fix.covariance))
        fix = tap_fix(s, m, end=pings - 1, n_pings=pings, config=config)
        without.append(nees(fix.position - truth, fix.covariance))
    assert abs(np.mean(exact) - 2.0) < 3.5 * np.sqrt(2 * 2 / runs), np.mean(exact)
    assert np.all(np.array(final) <= np.array(exact) + 1e-9)
    assert np.mean(without) > 5.0


def test_with_the_tides_drift_a_right_prediction_is_held_as_often_as_the_region_says():
    """The same drifting windows, each searched around the truth (the DR without offset): whether
    the prediction is allowed (``quality.holds_centre``) is asked of the likelihood with the
    drift, which holds the truth in at least 95 % of 200 windows less 3.5 Monte Carlo standard
    errors (measured: 0.93). The window's own region, which leaves the drift out, leaves the
    truth out of 47 % of them, far below its level: a check asking it ends right tracking."""
    from tangraph.matching.patch import _drift_covariance
    from tangraph.matching.tap_regions import _quality

    m = bowl()
    config = TapConfig(half_width=40.0, jackknife=False)
    runs, pings = 200, 20
    chol = np.linalg.cholesky(_drift_covariance(np.arange(pings, dtype=float), 0.1, 20.0))
    held, own = [], []
    for seed in range(runs):
        s = survey_on(m, noise=0.05, seed=seed, pings=pings, start=(600.0, 650.0), spacing=4.0,
                      offset=(0.0, 0.0))
        shift = chol @ np.random.default_rng(1000 + seed).normal(size=pings)
        s = s.replace(beam_depth=s.beam_depth + shift[:, None])
        fix = tap_fix(s, m, end=pings - 1, n_pings=pings, config=config, drift=(0.1, 20.0))
        held.append(fix.quality.holds_centre)
        region = fix.regions[RegionMethod.CALIBRATED]
        own.append(_quality(fix.surface, float(np.nanmin(fix.surface)), region, config, (1, 1)).holds_centre)
    p = 1.0 - config.alpha
    floor = p - 3.5 * np.sqrt(p * (1 - p) / runs)
    assert np.mean(held) >= floor, np.mean(held)
    assert np.mean(own) < floor, np.mean(own)  # the window's own region: not at its level
