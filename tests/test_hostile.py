"""Every hostile case of the robustness review, with what tangraph does with it and the test that
holds it to that.

A hostile but realistic user tried bad input, interruption and faults; each case below is one
of them: its class, the expected handling (a one-line refusal naming the option that settles it,
or handling as documented), and the test (``module::function``) that fails if tangraph falls
back to a silent wrong answer, a traceback or lost data. This module checks that the list is
whole (every class has its cases, every test named exists); the tests themselves run where they
live.
"""

from __future__ import annotations

import importlib
from collections import Counter

import pytest

MAPS, OUTPUTS, CLI, ESTIMATORS = "maps read wrongly", "outputs that destroy", "CLI contract", "estimators"

#: (case, class, expected handling, test)
CASES = [
    ("truncated classic NetCDF / GMT grd", MAPS, "refused: declared size vs file size",
     "tests.maps.test_hostile_maps::test_truncated_classic_netcdf_is_refused_naming_file_and_variable"),
    ("1e20 fill value without _FillValue", MAPS, "refused: pass nodata= / --nodata",
     "tests.maps.test_hostile_maps::test_unmarked_netcdf_fill_value_is_refused_then_masked_with_nodata"),
    ("XYZ with -99999", MAPS, "refused: pass --nodata",
     "tests.maps.test_hostile_maps::test_xyz_minus_99999_is_refused_then_masked_with_nodata"),
    ("read_map(nodata=) on NPZ", MAPS, "honoured",
     "tests.maps.test_hostile_maps::test_npz_reader_honours_nodata"),
    ("'bathy' holding positive depths", MAPS, "read as depths, not negated",
     "tests.maps.test_hostile_maps::test_water_named_variable_holding_positive_depths_is_not_negated"),
    ("mean_sea_height over positive depths", MAPS, "refused: pass sign= / --sign",
     "tests.maps.test_hostile_maps::test_mean_sea_height_over_positive_depths_is_refused"),
    ("depth units ft / feet / US survey foot", MAPS, "converted to metres",
     "tests.maps.test_hostile_maps::test_depth_units_attribute_is_converted_to_metres"),
    ("an unknown depth unit", MAPS, "refused: pass units= / --units",
     "tests.maps.test_hostile_maps::test_unknown_depth_unit_is_refused_naming_the_option"),
    ("coordinates in feet", MAPS, "converted to metres",
     "tests.maps.test_hostile_maps::test_coordinates_in_feet_are_converted_to_metres"),
    ("a CRS in US survey feet", MAPS, "metres, the same place",
     "tests.maps.test_hostile_maps::test_crs_in_us_survey_feet_gives_metres_and_the_same_place"),
    ("a GeoTIFF in US survey feet", MAPS, "metres",
     "tests.maps.test_hostile_maps::test_geotiff_in_us_survey_feet_reads_in_metres"),
    ("a geographic NetCDF grid", MAPS, "projected through the one projection step",
     "tests.maps.test_hostile_maps::test_lat_lon_netcdf_without_units_is_projected"),
    ("x/y grid with --crs EPSG:4326", MAPS, "projected",
     "tests.maps.test_hostile_maps::test_netcdf_x_y_with_a_geographic_crs_given_is_projected"),
    ("BathymetryMap with a geographic CRS", MAPS, "refused",
     "tests.maps.test_hostile_maps::test_bathymetry_map_refuses_a_geographic_crs"),
    ("a grid too wide for one transverse Mercator", MAPS, "refused with its scale error",
     "tests.maps.test_hostile_maps::test_grid_too_wide_for_one_transverse_mercator_is_refused_with_its_figure"),
    ("smoothing on another map than the survey's", MAPS, "refused unless --other-map",
     "tests.test_map_frame::test_a_survey_is_refused_on_a_map_it_was_not_made_on"),
    ("log in milliseconds, soundings in seconds", MAPS, "refused: the clocks do not overlap",
     "tests.formats.test_csv_xyz::test_soundings_on_another_clock_than_the_log_are_refused"),
    ("-o X --tum X", OUTPUTS, "refused: an output twice",
     "tests.cli.test_tracks::test_navigate_refuses_gis_without_crs_and_clashing_outputs"),
    ("survey import -o INPUT --force", OUTPUTS, "refused: an output over an input",
     "tests.cli.test_survey::test_cli_refuses_writing_over_an_input_and_the_wrong_file_count"),
    ("demo stopped by SIGTERM", OUTPUTS, "stops like Ctrl-C, no partial folder",
     "tests.test_outputs::test_sigterm_stops_the_demo_and_leaves_no_partial_folder"),
    ("stale .partial-PID folders", OUTPUTS, "removed by the next demo, live ones kept",
     "tests.test_outputs::test_a_stale_partial_folder_goes_and_a_live_one_stays"),
    ("track, TUM and figure interrupted", OUTPUTS, "all or none",
     "tests.test_outputs::test_an_error_while_writing_the_second_file_leaves_neither"),
    ("a grid declaring 200000^2 cells", CLI, "refused before reading, with its size (status 1)",
     "tests.cli.test_cli::test_a_grid_larger_than_free_memory_is_refused_before_reading"),
    ("--particles 1e9, --cell 0.001, --seed -1, --dpi 0 / 100000", CLI, "one line, status 2",
     "tests.cli.test_common::test_usage_errors_are_one_line_with_status_2"),
    ("--crs EPSG:999999", CLI, "one line, status 2",
     "tests.cli.test_cli::test_an_unknown_crs_is_bad_input"),
    ("a folder that cannot be written", CLI, "one line, status 1",
     "tests.cli.test_cli::test_a_folder_that_cannot_be_written_is_a_runtime_error_in_one_line"),
    ("a figure to an unknown suffix", CLI, "refused before any work",
     "tests.cli.test_common::test_a_figure_to_an_unknown_suffix_is_refused_before_any_work"),
    ("a lat/lon-swapped CSV log", CLI, "the impossible latitude named",
     "tests.formats.test_csv_xyz::test_an_impossible_latitude_is_named"),
    ("text in an XYZ soundings file", CLI, "file, line and column named",
     "tests.formats.test_csv_xyz::test_bad_input_is_one_line_naming_file_line_and_column"),
    ("piped into head", CLI, "ends quietly, status 141",
     "tests.cli.test_cli::test_a_closed_pipe_ends_quietly"),
    ("anything unforeseen", CLI, "one line, status 1; --debug shows the traceback",
     "tests.cli.test_cli::test_an_unforeseen_error_is_one_line_and_debug_shows_it"),
    ("maps info merimbula --cell 20", CLI, "valid: resampled",
     "tests.maps.test_catalogue::test_a_catalogue_map_takes_a_cell_but_not_file_options"),
    ("a private TANGRAPH_MAPS catalogue", CLI, "adds to the shipped maps",
     "tests.maps.test_catalogue::test_a_private_catalogue_adds_to_the_shipped_maps"),
    ("simulate --map FILE, then smooth", CLI, "the survey records the file and its read options",
     "tests.cli.test_tracks::test_a_survey_simulated_on_a_map_file_finds_it_again"),
    ("blocks of bad pings (footprints shifted, depths biased)", ESTIMATORS,
     "the smoother's GNC drops them; robustness study",
     "tests.graph.test_robust::test_gnc_finds_the_moved_fixes"),
    ("a fix resting on one bad ping", ESTIMATORS, "the ping-jackknife widens its covariance",
     "tests.matching.test_tap::test_a_fix_that_rests_on_one_ping_gets_the_jackknifes_large_covariance"),
    ("a surprising fix", ESTIMATORS, "held until a later fix agrees",
     "tests.graph.test_lost::test_a_surprising_fix_waits_for_the_next_to_agree"),
    ("a DR start far beyond its prior", ESTIMATORS, "online: lost, widened, relocalised, flagged",
     "tests.graph.test_lost::test_a_wrong_start_is_found_lost_and_relocalised"),
    ("a DR start far beyond its prior", ESTIMATORS, "smoother: the start prior dropped",
     "tests.graph.test_smoother::test_the_smoother_relocalises_the_whole_track"),
    ("a window that fits the map nowhere", ESTIMATORS, "refused as MISFIT",
     "tests.graph.test_fixes::test_a_misfit_window_is_refused_and_named"),
    ("a particle filter entirely off the map", ESTIMATORS, "keeps the DR and its growing covariance",
     "tests.filters.test_runner::test_a_cloud_off_the_map_keeps_the_dead_reckoning_and_its_growing_covariance"),
    ("leaving the map halfway", ESTIMATORS, "the graph's NEES stays honest off the map",
     "tests.graph.test_online::test_leaving_the_map_the_graph_stays_honest"),
    ("a particle filter on blocks of bad pings", ESTIMATORS, "ping_gate: the pings not weighed",
     "tests.filters.test_runner::test_pings_no_particle_explains_do_not_drag_the_cloud"),
    ("a particle filter every ping disagrees with", ESTIMATORS, "gate_pings: the cloud drawn afresh",
     "tests.filters.test_runner::test_a_cloud_every_ping_disagrees_with_is_drawn_afresh"),
    ("the smoother without its robust solve after a wrong start", ESTIMATORS,
     "the online navigator's widened start kept",
     "tests.graph.test_smoother::test_without_the_robust_solve_the_smoother_keeps_the_widened_start"),
    ("windows laid with DR errors not yet known", ESTIMATORS, "not refused as misfit when all fit as badly",
     "tests.graph.test_online_fixes::test_the_misfit_test_holds_a_window_against_the_ones_around_it"),
]


@pytest.mark.parametrize(("case", "kind", "handling", "test"), CASES, ids=[c[0] for c in CASES])
def test_every_case_has_a_test_that_exists(case, kind, handling, test):
    module, function = test.split("::")
    assert callable(getattr(importlib.import_module(module), function, None)), f"{case}: {test} is missing"


def test_every_class_of_the_review_has_its_cases():
    counts = Counter(kind for _, kind, _, _ in CASES)
    assert set(counts) == {MAPS, OUTPUTS, CLI, ESTIMATORS}
    assert counts[MAPS] >= 15 and counts[OUTPUTS] >= 5 and counts[CLI] >= 10 and counts[ESTIMATORS] >= 8
