"""The map's error estimated with the track (tangraph.graph.field_solve, smoother_terrain="field"):
the joint cost's gradient, the covariance against the bound of the same model, a planted error
recovered with its std, and the refined map from the CLI."""

import dataclasses

import gtsam
import numpy as np
import pytest
from scipy import sparse

from tangraph.errors import TangraphError
from tangraph.eval import bound_rmse, posterior_crb
from tangraph.eval.map_field import CombinedField, map_error_field
from tangraph.graph import GraphConfig, field_solve, smooth_survey, terrain_factors, terrain_solve
from tangraph.graph.calibration import MAP_OFFSET, TIDE
from tangraph.graph.online import GraphNavigator
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel, map_error, rotation_matrix
from tangraph.sensors.matern import matern_field
from tests.graph.terrain_cases import AXIS, lawnmower, noise_free, smooth_map

MODEL = NavigationModel(sounding_std=0.2, tide_std=1.0, speed_noise=0.02, initial_position_std=10.0,
                        speed_scale_std=0.02, heading_bias_std=0.03)


def with_error(bathymetry: BathymetryMap, std: float, length: float) -> BathymetryMap:
    return bathymetry.replace(depth_std=np.full(bathymetry.shape, std), correlation_length=length)


def flat_map(std: float, length: float) -> BathymetryMap:
    """A flat map at 50 m stated to err by ``std`` over ``length``."""
    return with_error(BathymetryMap(AXIS, AXIS, np.full((AXIS.size, AXIS.size), 50.0)), std, length)


#: the field smoother on a flat map: nothing tells the calibration, nothing to re-match
FIELD_ON_FLAT = GraphConfig().replace(smoother_terrain="field", rematch_iterations=0)
KNOWN_DR = {"speed_scale_std": 0.0, "heading_bias_std": 0.0}  # no calibration variable: the DR as it is


def biased_dr(survey, truth, scale=0.01, bias_deg=1.0):
    """The survey with a DR of speed scale ``scale`` and heading bias ``bias_deg`` about the start."""
    origin, bias = truth[0, :2], np.radians(bias_deg)
    dr = truth.copy()
    dr[:, :2] = origin + (1 + scale) * (truth[:, :2] - origin) @ rotation_matrix(bias).T
    dr[:, 2] = truth[:, 2] + bias
    return survey.replace(dr_pose=dr)


def test_the_normal_equations_are_the_joint_costs_gradient():
    # directional derivatives of odometry + priors + soundings + field prior, against A^T b - Q u
    bathymetry = with_error(smooth_map(), 0.3, 30.0)
    _, survey = lawnmower()
    survey = noise_free(survey, bathymetry)
    rng = np.random.default_rng(3)
    survey = survey.replace(beam_depth=survey.beam_depth + 0.2 * rng.standard_normal(survey.beam_depth.shape))
    nav = GraphNavigator(survey, bathymetry, GraphConfig(), model=MODEL).run(False)
    graph = terrain_solve._ping_graph(nav)
    terrain = terrain_factors.ping_terrain(survey, bathymetry, MODEL, graph.keys, nav.white, nav.origin,
                                           graph.calibrated)
    terrain = dataclasses.replace(terrain, map_offset_std=2.0)  # the map's offset a variable too
    factors = graph.with_fixes([], start=True).factor_graph()
    factors.add(gtsam.PriorFactorVector(TIDE, np.array([0.0]), gtsam.noiseModel.Isotropic.Sigma(1, 1.0)))
    factors.add(gtsam.PriorFactorVector(MAP_OFFSET, np.zeros(2), gtsam.noiseModel.Isotropic.Sigma(2, 2.0)))
    pose = survey.dr_pose + rng.normal(0.0, [0.5, 0.5, 0.01], survey.dr_pose.shape)
    calibration = np.array([0.01, 0.02])
    values = graph.values(pose, calibration)
    values.insert(TIDE, np.array([0.1]))
    values.insert(MAP_OFFSET, np.array([0.7, -0.4]))
    north, east = terrain_factors.footprints(terrain, bathymetry, pose, calibration)
    seen = np.isfinite(terrain.depth)
    hold = field_solve.FieldSoundings.at(map_error_field(north[seen], east[seen], nav.map_error), north, east,
                                         seen)
    terrain = dataclasses.replace(terrain, variance=0.04 + hold.nugget)
    layout = field_solve._Layout.of(values, hold.field.n_nodes)
    prior = sparse.csc_array(hold.field.precision)
    u = 0.3 * rng.standard_normal(hold.field.n_nodes)

    def unpack(v):
        return *terrain_solve._unpack(v, terrain, pose), np.asarray(v.atVector(MAP_OFFSET))

    def cost(v, x):
        p, c, t, o = unpack(v)
        return (factors.error(v) + 0.5 * float(x @ (prior @ x))
                + terrain_factors.terrain_cost(terrain, bathymetry, p, c, t, seen, hold.offset(x), o))

    _, gradient = field_solve._normal_equations(factors, values, u, terrain, bathymetry, hold, seen, unpack,
                                                layout, prior)
    for part in (slice(0, layout.n_gtsam), slice(layout.n_gtsam, layout.n), slice(0, layout.n)):
        step = np.zeros(layout.n)
        step[part] = 1e-5 * rng.standard_normal(step[part].size)
        up = cost(field_solve._retract(values, layout, step[:layout.n_gtsam]), u + step[layout.n_gtsam:])
        down = cost(field_solve._retract(values, layout, -step[:layout.n_gtsam]), u - step[layout.n_gtsam:])
        assert (up - down) / 2 == pytest.approx(-gradient @ step, rel=1e-4, abs=1e-9)


def test_the_covariance_is_the_bound_of_the_same_model():
    # noise-free soundings of a textured map stated to err by 0.3 m over 30 m, a DR 1 % / 1 deg
    # off: the smoother with the field claims about what the map-aware bound allows, a little
    # more (the bound takes the nodes' nugget as independent, the solve as shared within a cell;
    # the soundings alone, the map's error only widening their variances, claim far more)
    bathymetry = with_error(smooth_map(), 0.3, 30.0)
    truth, survey = lawnmower(start_error=(0.0, 0.0))
    survey = noise_free(biased_dr(survey, truth), bathymetry)
    bound = bound_rmse(posterior_crb(survey, bathymetry, MODEL, kind="smoother"))
    config = GraphConfig().replace(smoother_terrain="field", rematch_iterations=0)
    track = smooth_survey(survey, bathymetry, config, model=MODEL)
    claimed = np.sqrt(np.mean(np.trace(track.covariance[:, :2, :2], axis1=1, axis2=2)))
    assert bound <= claimed <= 1.15 * bound
    widened = smooth_survey(survey, bathymetry, config.replace(smoother_terrain="soundings"),
                            model=MODEL)
    assert np.sqrt(np.mean(np.trace(widened.covariance[:, :2, :2], axis1=1, axis2=2))) > 1.5 * bound
    info = track.meta["soundings"]
    assert info["field_nodes"] > 0 and info["field_spacing"] == pytest.approx(10.0)
    error = track.pose[:, :2] - truth[:, :2]
    assert np.sqrt(np.mean(np.sum(error**2, axis=1))) < bound


def test_with_a_field_of_map_offsets_the_covariance_is_the_bound_of_the_same_model():
    # a map whose stated error counts its soundings' positioning (1 m) through its slope, as a
    # gridded map's does; with that positioning error held as a field of offsets (range 150 m)
    # instead, the solve claims what the bound of that model allows (a little more, as above),
    # more than the depth error alone says, and the track stays within that claim
    bathymetry = smooth_map()
    north, east = np.meshgrid(AXIS, AXIS, indexing="ij")
    slope = np.sum(bathymetry.gradient_at(north, east) ** 2, axis=-1)
    bathymetry = bathymetry.replace(depth_std=np.sqrt(0.3**2 + slope), correlation_length=30.0)
    truth, survey = lawnmower(start_error=(0.0, 0.0))
    survey = noise_free(biased_dr(survey, truth), bathymetry)
    model = MODEL.replace(map_offset_std=1.0, map_offset_length=150.0)
    bound = bound_rmse(posterior_crb(survey, bathymetry, model, kind="smoother"))
    assert bound > 1.2 * bound_rmse(posterior_crb(survey, bathymetry, MODEL, kind="smoother"))
    config = GraphConfig().replace(smoother_terrain="field", rematch_iterations=0)
    track = smooth_survey(survey, bathymetry, config, model=model)
    claimed = np.sqrt(np.mean(np.trace(track.covariance[:, :2, :2], axis1=1, axis2=2)))
    assert bound <= claimed <= 1.15 * bound
    assert "map_offset" not in track.meta["soundings"]  # a field, not one offset
    error = track.pose[:, :2] - truth[:, :2]
    assert np.sqrt(np.mean(np.sum(error**2, axis=1))) < bound


def test_a_nugget_is_shared_by_the_points_of_one_cell_of_nodes():
    # three points in one cell of nodes give each other's nuggets (row sums), a point alone keeps
    # its own; in a combined field each field's cells count apart
    bathymetry = with_error(smooth_map(), 0.3, 30.0)
    field = map_error_field(np.array([100.0, 200.0]), np.array([100.0, 200.0]), map_error(bathymetry, MODEL))
    h, (n0, e0) = field.spacing, field.origin
    north = n0 + h * np.array([3.2, 3.5, 3.9, 6.5])
    east = e0 + h * np.array([4.1, 4.5, 4.8, 2.5])
    index, weight = field.weights(north, east)
    own = field.nugget(index, weight)
    shared = field_solve.shared_nugget(field, index, weight)
    root = np.sqrt(own[:3])
    np.testing.assert_allclose(shared[:3], root * root.sum())
    np.testing.assert_allclose(shared[3], own[3])
    assert np.all(shared[:3] > own[:3])
    combined = CombinedField((field, field))
    index2, weight2 = combined.weights(north, east)
    np.testing.assert_allclose(field_solve.shared_nugget(combined, index2, weight2), 2 * shared)


def blob(north, east, centre=(140.0, 160.0), height=0.8, width=12.0):
    return height * np.exp(-0.5 * ((north - centre[0]) ** 2 + (east - centre[1]) ** 2) / width**2)


def test_a_planted_map_error_is_recovered_with_its_std():
    # a flat map, a seafloor with a bump the map never had: the refined map has it, within its
    # stated std, and the track stays the DR's (a flat map tells nothing of where it lies)
    flat = flat_map(0.3, 30.0)
    model = NavigationModel(sounding_std=0.1, tide_std=1.0, speed_noise=0.02, initial_position_std=10.0,
                            **KNOWN_DR)
    truth, survey = lawnmower(start_error=(0.0, 0.0))
    north, east = survey.footprints(truth)
    rng = np.random.default_rng(5)
    survey = survey.replace(beam_depth=50.0 + blob(north, east) + 0.1 * rng.standard_normal(north.shape))
    track = smooth_survey(survey, flat, FIELD_ON_FLAT, model=model)
    np.testing.assert_allclose(track.pose[:, :2], survey.dr_pose[:, :2], atol=1e-6)
    refined = track.meta["refined_map"]
    assert refined.shape == flat.shape and refined.correlation_length == 30.0
    cell_n, cell_e = np.meshgrid(AXIS, AXIS, indexing="ij")
    surveyed = (np.abs(cell_n - 140.0) <= 50.0) & (np.abs(cell_e - 160.0) <= 70.0)
    truth_error = blob(cell_n, cell_e)
    before = np.sqrt(np.mean(truth_error[surveyed] ** 2))
    after = np.sqrt(np.mean((refined.depth - 50.0 - truth_error)[surveyed] ** 2))
    assert after < 0.3 * before
    at = (np.abs(cell_n - 140.0) < 1.0) & (np.abs(cell_e - 160.0) < 1.0)
    assert float(refined.depth[at][0]) - 50.0 == pytest.approx(0.8, abs=0.15)
    # never surer than it is (the bump is smoother than the prior's field, so it is cautious)
    z = (refined.depth - 50.0 - truth_error)[surveyed] / refined.depth_std[surveyed]
    assert np.sqrt(np.mean(z**2)) < 1.0 and np.max(np.abs(z)) < 3.0
    # the std shrinks where the soundings are (to what the nodes leave between them) and is the
    # prior's far from them
    assert np.max(refined.depth_std[surveyed]) < 0.7 * 0.3
    assert np.median(refined.depth_std[surveyed]) < 0.65 * 0.3
    np.testing.assert_allclose(refined.depth_std[0, 0], 0.3)
    np.testing.assert_allclose(refined.depth[0, 0], 50.0)


def test_a_map_without_error_is_solved_as_soundings():
    bathymetry = smooth_map()
    _, survey = lawnmower()
    survey = noise_free(survey, bathymetry)
    config = GraphConfig().replace(smoother_terrain="field", rematch_iterations=0)
    field = smooth_survey(survey, bathymetry, config, model=MODEL)
    soundings = smooth_survey(survey, bathymetry, config.replace(smoother_terrain="soundings"),
                              model=MODEL)
    np.testing.assert_array_equal(field.pose, soundings.pose)
    assert "refined_map" not in field.meta and "field_nodes" not in field.meta["soundings"]


def test_smooth_writes_the_refined_map(tmp_path, capsys):
    from tangraph.cli import main
    from tangraph.maps import read_map, write_map
    from tangraph.survey import write_survey

    bathymetry = smooth_map()
    _, survey = lawnmower()
    survey = noise_free(survey, bathymetry)
    map_file, survey_file = tmp_path / "map.nc", tmp_path / "survey.nc"
    write_map(bathymetry, map_file)
    write_survey(survey, survey_file)
    model = tmp_path / "model.toml"
    model.write_text("sounding_std = 0.2\ntide_std = 1.0\nspeed_noise = 0.02\ninitial_position_std = 10.0\n")
    refined, out = tmp_path / "refined.nc", tmp_path / "track.csv"
    base = ["smooth", str(survey_file), "--map", str(map_file), "--dr-model", str(model), "-q",
            "-o", str(out)]
    # a map that states no error has nothing to refine: said in one line, nothing written
    assert main([*base, "--refined-map", str(refined)]) == 2
    err = capsys.readouterr().err
    assert "states no error" in err and "map_change_std" in err and not refined.exists() and not out.exists()
    assert main([*base, "--refined-map", str(tmp_path / "refined.map")]) == 2
    assert "cannot tell the format" in capsys.readouterr().err
    model.write_text(model.read_text() + "map_std = 0.2\nmap_correlation_length = 30.0\n")
    assert main([*base, "--refined-map", str(refined)]) == 0
    assert "map error    estimated with the track on" in capsys.readouterr().out
    written = read_map(refined)
    assert written.shape == bathymetry.shape and written.depth_std is not None
    assert written.correlation_length == pytest.approx(30.0)
    # noise-free soundings of the map itself: the refined map stays it, and is surer under the track
    np.testing.assert_allclose(written.depth, bathymetry.depth, atol=0.05)
    assert np.nanmin(written.depth_std) < 0.5 * 0.2 and np.nanmax(written.depth_std) == pytest.approx(0.2)
    assert out.exists()


def test_patches_are_squares_of_a_few_ranges_per_field():
    bathymetry = with_error(smooth_map(), 0.3, 30.0)
    field = map_error_field(np.array([100.0, 300.0]), np.array([100.0, 300.0]), map_error(bathymetry, MODEL))
    patch = field_solve.patches(field)
    north, east = field.nodes()
    side = field_solve.PATCH_LENGTHS * 30.0
    for p in np.unique(patch):
        at = patch == p
        assert np.ptp(north[at]) < side and np.ptp(east[at]) < side
    assert np.unique(patch).size >= (np.ptp(north) // side) * (np.ptp(east) // side)
    combined = CombinedField((field, field))
    both = field_solve.patches(combined)
    assert set(both[:field.n_nodes]).isdisjoint(both[field.n_nodes:])


def test_patch_factors_weigh_a_patch_against_the_survey():
    patch = np.repeat(np.arange(4), 50)
    ones = np.ones(patch.size)

    def found(square_per_patch, redundancy=0.4):
        return {"field_nodes": np.asarray(square_per_patch, float)[patch] * redundancy,
                "field_node_redundancy": np.full(patch.size, redundancy)}

    # as the model says: 1; the whole map twice as wrong: 2 everywhere (prior and data agree)
    np.testing.assert_allclose(field_solve.patch_factors(found([1, 1, 1, 1]), ones, patch), 1.0)
    np.testing.assert_allclose(field_solve.patch_factors(found([4, 4, 4, 4]), ones, patch), 2.0)
    # never below the stated std
    np.testing.assert_allclose(field_solve.patch_factors(found([0.2, 0.2, 0.2, 0.2]), ones, patch), 1.0)
    # one patch five times as wrong as stated: it alone is grown by about that
    one = field_solve.patch_factors(found([25, 1, 1, 1]), ones, patch)
    assert one[0] > 4.0 and np.all(one[patch > 0] < 1.0 + 0.5 * (one[0] - 1.0) / 4.0)
    # a patch no sounding sees (no redundancy) takes the survey's scale
    empty = found([9, 9, 9, 0])
    empty["field_node_redundancy"][patch == 3] = 0.0
    np.testing.assert_allclose(field_solve.patch_factors(empty, ones, patch), 3.0)
    # the factors found are of the field as currently scaled: twice the stated std and as wrong as
    # that says, they stay
    np.testing.assert_allclose(field_solve.patch_factors(found([1, 1, 1, 1]), 2 * ones, patch), 2.0)


def test_a_hold_scaled_per_node_is_the_scalar_scaling_when_uniform():
    bathymetry = with_error(smooth_map(), 0.3, 30.0)
    _, survey = lawnmower()
    north, east = survey.footprints(survey.true_pose)
    seen = np.ones(north.shape, bool)
    seen[::7, 3] = False
    field = map_error_field(north[seen], east[seen], map_error(bathymetry, MODEL))
    hold = field_solve.FieldSoundings.at(field, north, east, seen)
    twice = hold.scaled(np.full(hold.field.n_nodes, 2.0))
    np.testing.assert_allclose(twice.field.std, 2 * hold.field.std)
    np.testing.assert_allclose(twice.nugget, 4 * hold.nugget)
    assert np.all(np.isnan(twice.nugget[~seen]))
    ratio = hold.variance_ratio(np.full(hold.field.n_nodes, 2.0))
    np.testing.assert_allclose(ratio[seen], 4.0)
    np.testing.assert_allclose(ratio[~seen], 1.0)


def test_a_patch_far_off_its_stated_error_is_given_its_own():
    # a flat map stated to err by 0.1 m over 10 m: so it does in the west, three times that in the
    # east. The solve grows the error of the eastern patches by about three and leaves the western
    # ones at what is stated, and the refined map is honest on both sides
    flat = flat_map(0.1, 10.0)
    model = NavigationModel(sounding_std=0.05, tide_std=1.0, speed_noise=0.02, initial_position_std=10.0,
                            **KNOWN_DR)
    truth, survey = lawnmower(start_error=(0.0, 0.0))
    north, east = survey.footprints(truth)
    rng = np.random.default_rng(8)
    cell_n, cell_e = np.meshgrid(AXIS, AXIS, indexing="ij")
    error = matern_field(AXIS, AXIS, 1.0, 10.0, rng=rng) * np.where(cell_e > 160.0, 0.3, 0.1)
    seafloor = BathymetryMap(AXIS, AXIS, 50.0 + error)
    noise = 0.05 * rng.standard_normal(north.shape)
    survey = survey.replace(beam_depth=seafloor.depth_at(north, east) + noise)
    track = smooth_survey(survey, flat, FIELD_ON_FLAT, model=model)
    assert 2.0 < track.meta["soundings"]["field_factor_max"] < 4.0
    refined = track.meta["refined_map"]
    z = (refined.depth - 50.0 - error) / refined.depth_std
    surveyed = (np.abs(cell_n - 140.0) <= 40.0) & (np.abs(cell_e - 160.0) <= 80.0)
    east_side, west_side = surveyed & (cell_e > 170.0), surveyed & (cell_e < 150.0)
    assert np.sqrt(np.mean(z[east_side] ** 2)) < 1.3 and np.sqrt(np.mean(z[west_side] ** 2)) < 1.3
    assert np.median(refined.depth_std[east_side]) > 1.5 * np.median(refined.depth_std[west_side])


def test_the_map_offset_is_recovered_and_the_track_kept():
    # the map lies 3 m south and 2 m east of where its coordinates say (the seafloor at p is the
    # map's depth at p + (3, -2)), the DR is exact: with the offset a variable the solve finds it
    # and keeps the track; without, the track is pulled towards where the map fits
    bathymetry = with_error(smooth_map(), 0.05, 30.0)
    truth, survey = lawnmower(start_error=(0.0, 0.0))
    north, east = survey.footprints(truth)
    rng = np.random.default_rng(4)
    depth = bathymetry.depth_at(north + 3.0, east - 2.0) + 0.05 * rng.standard_normal(north.shape)
    survey = survey.replace(beam_depth=depth)
    model = NavigationModel(sounding_std=0.05, tide_std=0.5, speed_noise=0.02, initial_position_std=2.0,
                            speed_scale_std=0.02, heading_bias_std=0.03, map_offset_std=5.0)
    config = GraphConfig().replace(smoother_terrain="field", rematch_iterations=0)
    track = smooth_survey(survey, bathymetry, config, model=model)
    info = track.meta["soundings"]
    found, std = np.array(info["map_offset"]), np.array(info["map_offset_std"])
    # the offset is known as well as the track's absolute position (the start's 2 m), the track
    # on the map (the track plus the offset) far better
    assert np.all(std < 2.0) and np.all(np.abs(found - [3.0, -2.0]) < 3 * std)
    on_map = track.pose[:, :2] - truth[:, :2] + found
    assert np.all(np.abs(np.mean(on_map, axis=0) - [3.0, -2.0]) < 0.2)
    kept = np.sqrt(np.mean(np.sum((track.pose[:, :2] - truth[:, :2]) ** 2, axis=1)))
    pulled = smooth_survey(survey, bathymetry, config, model=model.replace(map_offset_std=0.0))
    assert "map_offset" not in pulled.meta["soundings"]
    moved = np.sqrt(np.mean(np.sum((pulled.pose[:, :2] - truth[:, :2]) ** 2, axis=1)))
    assert kept < 1.0 < moved


def test_a_flat_map_says_nothing_of_its_offset():
    flat = flat_map(0.1, 30.0)
    model = NavigationModel(sounding_std=0.1, tide_std=1.0, speed_noise=0.02, initial_position_std=10.0,
                            map_offset_std=5.0, **KNOWN_DR)
    _, survey = lawnmower(start_error=(0.0, 0.0))
    survey = noise_free(survey, flat)
    track = smooth_survey(survey, flat, FIELD_ON_FLAT, model=model)
    np.testing.assert_allclose(track.meta["soundings"]["map_offset_std"], 5.0, rtol=1e-3)
    np.testing.assert_allclose(track.pose[:, :2], survey.dr_pose[:, :2], atol=1e-6)
    with pytest.raises(TangraphError, match="map_offset_std"):
        NavigationModel(map_offset_std=-1.0)
