"""The online navigator's window fixes (tangraph.graph.online_fixes): widened by the map error their
soundings share, judged against the windows around them (the misfit test), and the point-mass front
end's depth faults and tide steps."""

from __future__ import annotations

import numpy as np

from tangraph.fix_records import FixStatus
from tangraph.graph import GraphConfig, GraphNavigator, navigate_online, online_fixes
from tangraph.sensors import NavigationModel
from tangraph.track import position_errors

CONFIG = GraphConfig(key_interval=20.0)


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


def test_the_misfit_test_holds_a_window_against_the_ones_around_it(small_survey, rough_map):
    """At the start of a survey every patch is laid with DR whose constant errors are unknown and
    fits the map worse than the soundings' noise: from the third window on, windows that all fit
    as badly are not refused; one that fits far worse than those around it is."""
    nav = GraphNavigator(small_survey, rough_map, CONFIG)
    noise = nav.model.measurement_std
    assert online_fixes.misfit_noise(nav, 9, 0.5 * noise) == noise  # never below the model's
    assert online_fixes.misfit_noise(nav, 19, 8.0 * noise) == noise  # two windows: too few to say
    bad = [9.0, 10.0, 8.5, 9.5, 9.0, 8.0, 10.0, 9.0, 8.5]
    for k, sigma in zip(range(29, 119, 10), bad, strict=True):
        limit = CONFIG.fixes.misfit_ratio * online_fixes.misfit_noise(nav, k, sigma * noise)
        assert sigma * noise < limit  # all as bad: none refused
    for k in range(119, 239, 10):
        online_fixes.misfit_noise(nav, k, noise)  # the DR's errors known: the windows fit
    # one bad one
    assert 5.0 * noise > CONFIG.fixes.misfit_ratio * online_fixes.misfit_noise(nav, 239, 5.0 * noise)
    kept = list(nav._residuals)
    online_fixes.misfit_noise(nav, 239, 5.0 * noise)  # the same window judged again (after a widening)
    assert list(nav._residuals) == kept and len(kept) == 10  # it pushes no older window out


def test_a_step_of_the_depths_is_a_tide_step_a_block_of_them_a_fault(rough_map):
    """The front end holds one tide. A block of 20 pings 6 m deep is a depth fault (its windows
    are no evidence, the track keeps to the truth); the depths stepping by 1.5 m for good is a
    step of the tide: the graph holds a new one and learns it."""
    import dataclasses

    from conftest import small_scenario

    from tangraph.sim.scenario import simulate

    scenario = small_scenario()
    scenario = dataclasses.replace(scenario, sonar=dataclasses.replace(scenario.sonar, tide=1.5))
    survey = simulate(scenario, rng=np.random.default_rng(62), bathymetry=rough_map, seed=62)
    clean = navigate_online(survey, rough_map, GraphConfig().replace(front_end="pmf"))
    n = survey.n_pings
    ping = np.arange(n)[:, None]
    block = survey.replace(beam_depth=survey.beam_depth + np.where(ping // 20 == n // 40, 6.0, 0.0))
    faulty = navigate_online(block, rough_map, GraphConfig().replace(front_end="pmf"))
    assert any(f.status is FixStatus.MISFIT and f.detail.startswith("depth fault") for f in faulty.fixes)
    assert faulty.meta["tide"]["steps"] == [] and abs(faulty.meta["tide"]["tide"] - 1.5) < 0.1
    rmse = {name: np.sqrt(np.mean(position_errors(t, survey.true_pose) ** 2))
            for name, t in (("clean", clean), ("faulty", faulty))}
    assert rmse["faulty"] < 1.5 * rmse["clean"] + 0.5, rmse
    stepped = survey.replace(beam_depth=survey.beam_depth + np.where(ping >= n // 2, 1.5, 0.0))
    track = navigate_online(stepped, rough_map, GraphConfig().replace(front_end="pmf"))
    assert len(track.meta["tide"]["steps"]) == 1 and n // 2 < track.meta["tide"]["steps"][0] < n // 2 + 80
    assert abs(track.meta["tide"]["tide"] - 3.0) < 0.1
    errors = position_errors(track, survey.true_pose)
    assert np.sqrt(np.mean(errors[-n // 4:] ** 2)) < 2.0 * rmse["clean"] + 0.5
