"""NavigationModel: validation naming the field, construction from a DR model, a survey, a TOML file."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.sensors import DeadReckoningModel, NavigationModel, load_navigation_model


@pytest.mark.parametrize("field, value", [("speed_noise", -0.1), ("sounding_std", 0.0), ("tide_std", np.nan),
                                          ("speed_scale_std", np.inf), ("initial_position_std", "ten"),
                                          ("heading_bias", 4.0), ("map_std", True),
                                          ("robust_kernel", "tukey"), ("robust_parameter", 0.0),
                                          ("fix_inflation", 0.5), ("odometry_min_std", -1.0),
                                          ("odometry_min_heading_std", np.nan)])
def test_bad_values_are_refused_naming_the_field(field, value):
    with pytest.raises(TangraphError, match=f"NavigationModel.{field}"):
        NavigationModel(**{field: value})


def test_a_known_constant_error_has_a_std_of_zero():
    model = NavigationModel(speed_scale=0.01, speed_scale_std=0.0, heading_bias_std=0.0)
    assert model.calibration_std.tolist() == [0.0, 0.0] and model.calibration_prior[0] == 0.01
    with pytest.raises(TangraphError, match="NavigationModel.heading_bias_std must be >= 0"):
        NavigationModel(heading_bias_std=-0.1)


def test_from_dead_reckoning_takes_white_errors_and_turns_constants_into_priors():
    dr = DeadReckoningModel(heading_bias=np.deg2rad(3.5), speed_scale=0.03, speed_noise=0.05,
                            heading_walk=1e-4, start_position_std=7.0)
    model = NavigationModel.from_dead_reckoning(dr)
    assert (model.speed_noise, model.heading_walk, model.initial_position_std) == (0.05, 1e-4, 7.0)
    assert model.speed_scale == 0.0 and model.heading_bias == 0.0  # the truth is not known
    np.testing.assert_allclose(model.calibration_std, [0.03, np.deg2rad(3.5)])
    assert model.dead_reckoning.speed_scale == 0.0 and model.dead_reckoning.heading_bias == 0.0
    assert NavigationModel.from_dead_reckoning(dr, speed_noise=0.2).speed_noise == 0.2
    compass = NavigationModel.from_dead_reckoning(dr.__class__(heading_turn_std=0.07))
    assert compass.heading_turn_std == 0.07 and compass.dead_reckoning.heading_turn_std == 0.07


def test_the_heading_errors_turn_part_in_degrees_and_its_errors(tmp_path):
    model = NavigationModel.from_mapping({"heading_turn_std_deg": 4.0})
    assert model.heading_turn_std == pytest.approx(np.deg2rad(4.0))
    with pytest.raises(TangraphError, match="NavigationModel.heading_turn_std must be >= 0"):
        NavigationModel(heading_turn_std=-0.1)


def test_from_survey_needs_the_settings():
    from tangraph.survey import Survey

    ones = np.ones((3, 1))
    bare = Survey(time=np.arange(3.0), dr_pose=np.zeros((3, 3)), vehicle_depth=ones[:, 0],
                  beam_forward=0 * ones, beam_starboard=0 * ones, beam_depth=ones)
    with pytest.raises(TangraphError, match="NavigationModel"):
        NavigationModel.from_survey(bare)
    settings = {"dead_reckoning": {"speed_noise": 0.1}, "sonar": {"depth_noise": 0.2}}
    model = NavigationModel.from_survey(bare.replace(meta={"settings": settings}))
    assert model.speed_noise == 0.1 and model.sounding_std == pytest.approx(0.3)
    assert model.map_offset_std == 0.0 and model.map_offset_length == 0.0
    # a prior map gridded from an earlier survey states the offset its gridding kept
    placed = {"settings": settings, "seafloor": {"map_offset_std": 1.4, "map_offset_length": 390.0}}
    model = NavigationModel.from_survey(bare.replace(meta=placed))
    assert model.map_offset_std == 1.4 and model.map_offset_length == 390.0
    assert model.map_change_std == 0.0
    # a seafloor that changed since the earlier survey states the change the world drew
    changed = {"settings": settings, "seafloor": {"map_change_std": 0.3, "map_change_length": 30.0}}
    model = NavigationModel.from_survey(bare.replace(meta=changed))
    assert (model.map_change_std, model.map_change_length, model.map_offset_std) == (0.3, 30.0, 0.0)
    assert model.measurement_std == pytest.approx(np.sqrt(0.3**2 + 0.3**2))
    with pytest.raises(TangraphError, match="map_change_std must be >= 0"):
        NavigationModel(map_change_std=-0.1)
    with pytest.raises(TangraphError, match="map_offset_length must be >= 0"):
        NavigationModel(map_offset_length=-1.0)


def test_toml_file_in_degrees_and_its_errors(tmp_path):
    path = tmp_path / "dr.toml"
    path.write_text("speed_noise = 0.04\nheading_bias_std_deg = 1.5\n[other]\n")
    with pytest.raises(TangraphError, match="unknown key 'other'"):
        load_navigation_model(path)
    path.write_text("[navigation]\nspeed_noise = 0.04\nheading_bias_std_deg = 1.5\n")
    model = load_navigation_model(path)
    assert model.speed_noise == 0.04 and model.heading_bias_std == pytest.approx(np.deg2rad(1.5))
    path.write_text("speed_noise = -1\n")
    with pytest.raises(TangraphError, match=r"dr.toml: NavigationModel.speed_noise must be >= 0"):
        load_navigation_model(path)
    path.write_text("heading_bias_std = 0.1\nheading_bias_std_deg = 2\n")
    with pytest.raises(TangraphError, match="given twice"):
        load_navigation_model(path)
    with pytest.raises(TangraphError, match="does not exist"):
        load_navigation_model(tmp_path / "missing.toml")


def test_the_map_error_from_toml_and_the_old_switch_refused(tmp_path):
    path = tmp_path / "model.toml"
    path.write_text("[navigation]\nmap_std = 0.2\nmap_correlation_length = 30.0\n")
    model = load_navigation_model(path)
    assert (model.map_std, model.map_correlation_length) == (0.2, 30.0)
    path.write_text("[navigation]\nmap_correlation_length = -1\n")
    with pytest.raises(TangraphError, match="map_correlation_length must be >= 0"):
        load_navigation_model(path)
    path.write_text("[navigation]\nmap_error_shared = true\n")
    with pytest.raises(TangraphError, match="map_error_shared is no longer a setting.*correlation_length"):
        load_navigation_model(path)


def test_the_fix_error_model_from_toml(tmp_path):
    """The graph's fix error model (kernel, threshold, inflation) and odometry floors are model
    fields: read from a model file, kept in the track's metadata as they were given."""
    path = tmp_path / "model.toml"
    path.write_text('[navigation]\nrobust_kernel = "cauchy"\nrobust_parameter = 3.0\nfix_inflation = 2.0\n'
                    "odometry_min_std = 0.02\n")
    model = load_navigation_model(path)
    assert (model.robust_kernel, model.robust_parameter, model.fix_inflation, model.odometry_min_std) == \
        ("cauchy", 3.0, 2.0, 0.02)
    assert model.as_dict()["robust_kernel"] == "cauchy"
    assert NavigationModel(**model.as_dict()) == model
