"""A window's fix judged (tangraph.graph.fixes): its record and status, the misfit test, and the
search's half-width and step as the config gives them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.graph import FixStatus, GraphConfig
from tangraph.graph.fixes import check_tide_drift, judge_fix, search_half_width, search_step
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import TapConfig, tap_fix
from tangraph.sensors import NavigationModel

CONFIG = GraphConfig(key_interval=20.0)


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


def _flagged(fix, *reasons):
    quality = dataclasses.replace(fix.quality, reasons=tuple(reasons))
    return dataclasses.replace(fix, quality=quality)


def test_fix_outcomes_are_records_with_a_status(biased_survey, rough_map):
    from tangraph.fix_records import FixStatus
    from tangraph.graph.fixes import judge_fix
    from tangraph.matching import tap_fix

    config = GraphConfig()
    fix = tap_fix(biased_survey.replace(dr_pose=biased_survey.true_pose), rough_map, 59, 20, config.fixes.tap,
                  prior=biased_survey.true_pose[59, :2])
    predicted, cov = biased_survey.true_pose[59], np.eye(3) * 4.0
    assert judge_fix(fix, predicted, cov, config, 50.0).record.status is FixStatus.ACCEPTED
    two = _flagged(fix, "multimodal: 2 basins")
    used = judge_fix(two, predicted, cov, config, 50.0)
    assert used.accepted and used.record.status is FixStatus.ACCEPTED and "multimodal" in used.record.reason
    refused = judge_fix(two, predicted, cov, config.replace(accept_multimodal=False), 50.0)
    assert refused.record.status is FixStatus.MULTIMODAL and not refused.accepted
    flat = judge_fix(_flagged(fix, "uninformative: touches the edge"), predicted, cov, config, 50.0)
    assert flat.record.status is FixStatus.UNINFORMATIVE
    far = judge_fix(fix, predicted + np.array([200.0, 0.0, 0.0]), cov, config, 50.0)
    assert far.record.status is FixStatus.GATE and far.record.nis > 13.8


def test_a_misfit_window_is_refused_and_named(small_survey, rough_map):
    fix = tap_fix(small_survey, rough_map, 59, 20, TapConfig(half_width=30.0),
                  prior=small_survey.true_pose[59, :2])
    outcome = judge_fix(fix, small_survey.true_pose[59], np.eye(3), CONFIG, 30.0, noise=fix.sigma / 5.0)
    assert outcome.record.status is FixStatus.MISFIT and "5.0 x the model's" in outcome.record.detail
    assert judge_fix(fix, small_survey.true_pose[59], np.eye(3), CONFIG, 30.0,
                     noise=fix.sigma).record.status is not FixStatus.MISFIT


@pytest.mark.parametrize("changes, message", [
    ({"tap": TapConfig(criterion="msd")}, "criterion 'msd' takes the depths as reduced"),
    ({"tap": TapConfig(criterion="mad")}, "criterion 'mad'"),
    ({"front_end": "pmf"}, "front_end = 'pmf' holds one tide"),
    ({"smoother_terrain": "field"}, "smoother_terrain = 'field' holds one tide"),
])
def test_a_graph_that_holds_the_tide_constant_refuses_a_drifting_one(changes, message, small_survey,
                                                                   rough_map):
    config = GraphConfig().replace(**changes)
    drifting = NavigationModel(tide_drift_std=0.2, tide_drift_time=200.0)
    check_tide_drift(config, NavigationModel())  # a constant tide: every setting holds
    assert check_tide_drift(GraphConfig(), drifting) is drifting  # the defaults estimate each window's tide
    tracking = GraphConfig().replace(terrain="soundings", acquire="pmf")  # follows the drift (online_tide)
    assert check_tide_drift(tracking, drifting) is drifting
    with pytest.raises(TangraphError, match=message):
        check_tide_drift(config, drifting)
    with pytest.raises(TangraphError, match="tide_drift_std = 0.2 m"):  # where the graph starts
        from tangraph.graph import navigate_online

        navigate_online(small_survey, rough_map, config, model=drifting)


def test_a_fix_is_widened_by_the_drift_the_graphs_other_fixes_share():
    from tangraph.graph.fixes import fix_drift

    time = np.arange(0.0, 1000.0, 2.0)  # a ping every 2 s
    config = GraphConfig().replace(fix_spacing=10)  # a fix every 20 s
    assert fix_drift(NavigationModel(), config, time) is None
    std, forget = fix_drift(NavigationModel(tide_drift_std=0.3, tide_drift_time=100.0), config, time)
    lags = np.arange(-200, 201) * 20.0
    assert forget == 100.0
    assert std**2 == pytest.approx(0.09 * np.sum(np.exp(-np.abs(lags) / 100.0)), rel=1e-9)


def test_a_map_that_states_its_drift_gives_it_to_a_model_that_states_none(small_survey, rough_map):
    from tangraph.eval import posterior_crb
    from tangraph.navigation import navigate

    model = NavigationModel.from_survey(small_survey)
    drifting_map = rough_map.replace(error_drift=(0.2, 150.0))
    stated = model.with_map(drifting_map)
    assert stated.tide_drift == (0.2, 150.0) and model.with_map(rough_map) is model
    own = model.replace(tide_drift_std=0.1, tide_drift_time=50.0)
    assert own.with_map(drifting_map) is own  # a model's own drift is kept
    assert model.replace(tide_drift_std=0.0).with_map(drifting_map).tide_drift is None  # and its "none"
    # every estimator and the bound take the map's as if the model stated it
    for method in ("isam2", "pf"):
        from_map = navigate(small_survey, drifting_map, method, rng=np.random.default_rng(0), model=model)
        told = navigate(small_survey, rough_map, method, rng=np.random.default_rng(0), model=stated)
        np.testing.assert_array_equal(from_map.pose, told.pose)
        plain = navigate(small_survey, rough_map, method, rng=np.random.default_rng(0), model=model)
        assert not np.array_equal(plain.pose, told.pose)
    bound = posterior_crb(small_survey, drifting_map, model, kind="filter")
    np.testing.assert_array_equal(bound.position_cov, posterior_crb(small_survey, rough_map, stated,
                                                                    kind="filter").position_cov)
    with pytest.raises(TangraphError, match="map's error_drift"):
        navigate(small_survey, drifting_map, "isam2", GraphConfig().replace(tap=TapConfig(criterion="msd")),
                 model=model)
