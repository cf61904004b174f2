"""The seafloor's change since its map, measured by a later survey's check lines
(tangraph.eval.map_change): a known change recovered from simulated soundings, none found where
the seafloor did not change, and bad input refused."""

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.eval.map_change import MapChange, measure_change
from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel
from tests.eval.line_cases import (
    AXIS_MAP_E,
    AXIS_MAP_N,
    MAP_LENGTH,
    MAP_STD,
    SOUNDING_STD,
    earlier_map,
    field_on_lines,
    later_survey,
    line_survey,
    seafloor,
)

MODEL = NavigationModel(sounding_std=SOUNDING_STD)

@pytest.mark.parametrize("seed", [1, 2])
def test_a_known_change_is_recovered_from_alater_survey(seed):
    """A change of 0.25 m and range 40 m: its std within 12 % (about three times the spread of
    the robust estimate over 47 000 soundings, sharing their change over 8 lines of 2 km), its
    range within a factor of 2 (about 300 windows of 50 m, a few dozen independent ones per
    line: the range moves their spread little)."""
    found = measure_change([later_survey(seed, 0.25)], earlier_map(), MODEL)
    assert isinstance(found, MapChange)
    assert found.std == pytest.approx(0.25, rel=0.12)
    assert 20.0 < found.length < 80.0 and found.length_bound is None
    assert found.sounding_z > 1.7  # 2.0 expected: the map's own statement does not hold a survey later
    assert found.windows > 250 and found.soundings > 40_000
    assert found.model_fields() == {"map_change_std": round(found.std, 4),
                                    "map_change_length": round(found.length, 1)}
    assert "change since the map: std" in found.summary()
    # the model's fields state it, and the map's error then carries it as a field of its own
    from tangraph.sensors import map_error

    error = map_error(earlier_map(), MODEL.replace(**found.model_fields()))
    lengths = [p.correlation_length for p in error.components()]
    assert lengths == [MAP_LENGTH, pytest.approx(found.length, abs=0.1)]
    assert float(error.std[0, 0]) == pytest.approx(np.hypot(MAP_STD, found.std), abs=1e-4)


def test_an_unchanged_seafloor_shows_no_change():
    found = measure_change([later_survey(3, 0.0)], earlier_map(), MODEL.replace(map_change_std=0.5))
    assert found.std < 0.03  # the model's own change is not what is measured
    assert found.sounding_z == pytest.approx(1.0, abs=0.1)


def test_bad_input_is_refused():
    survey = later_survey(4, 0.0)
    with pytest.raises(TangraphError, match="window must be > 0"):
        measure_change([survey], earlier_map(), window=0.0)
    with pytest.raises(TangraphError, match="measure_change: position_std must be >= 0"):
        measure_change([survey], earlier_map(), position_std=-1.0)
    with pytest.raises(TangraphError, match="no survey given"):
        measure_change([], earlier_map())
    with pytest.raises(TangraphError, match="'gps-less' has no reference track"):
        measure_change([survey.replace(true_pose=None, meta={"name": "gps-less"})], earlier_map())
    far = earlier_map().replace(north=AXIS_MAP_N + 5000.0)
    with pytest.raises(TangraphError, match="measure_change: survey 'later 4': the survey does not overlap "
                                            "map 'earlier'.*; measure with surveys of the map's area"):
        measure_change([survey], far)
    with pytest.raises(TangraphError, match="0 soundings of the surveys lie in the cells of map 'earlier'"):
        measure_change([survey], earlier_map(), measured=np.zeros(earlier_map().shape, bool))
    # a survey given twice (here under another name and shifted into another frame) counts twice
    moved = survey.replace(meta={"name": "again", "origin": [0.0, 0.0]})
    with pytest.raises(TangraphError, match="measure_change: 'a.nc' and 'b.nc' hold the same 15680 pings"):
        measure_change([survey, moved], earlier_map(), names=["a.nc", "b.nc"])
    with pytest.raises(TangraphError, match="2 names for 1 surveys"):
        measure_change([survey], earlier_map(), names=["a.nc", "b.nc"])
    # a map that states no error: its own error cannot be told from a change, unless the model states it
    bare = earlier_map().replace(depth_std=None, correlation_length=None)
    with pytest.raises(TangraphError, match="map 'earlier' states no error .* CLI --map-std"):
        measure_change([survey], bare)
    assert measure_change([survey], bare, MODEL.replace(map_std=MAP_STD, map_correlation_length=MAP_LENGTH),
                          measured=np.ones(bare.shape, bool)).std < 0.03
    with pytest.raises(TangraphError, match=r"measured cells of shape \(3, 3\), the map 'earlier' \(100"):
        measure_change([survey], earlier_map(), measured=np.ones((3, 3), bool))


def test_a_range_rests_on_enough_windows():
    """One line of 400 m: 8 windows of 50 m, too few for a range, which is left to the map's."""
    survey = later_survey(8, 0.25).pings(0, 400)
    found = measure_change([survey], earlier_map(), MODEL)
    assert found.windows < 10 and found.std > 0.15
    assert (found.length, found.length_bound) == (0.0, "unmeasured")
    assert "too few windows to measure it" in found.summary()


def test_only_the_measured_cells_count_and_a_gap_stated_wide_hides_no_change():
    """The map's eastern half was filled and states a wide error (1 m): measured where its data
    are, the change is found as before; taken everywhere, the gaps' wide statement would hide
    it. Told the cells, only those count."""
    survey, earlier = later_survey(6, 0.25), earlier_map()
    gaps = np.zeros(earlier.shape, bool)
    gaps[:, 250:] = True
    wide = earlier.replace(depth_std=np.where(gaps, 1.0, MAP_STD))
    found = measure_change([survey], wide, MODEL, measured=~gaps)
    assert found.cells == "measured" and found.std == pytest.approx(0.25, rel=0.12)
    assert 20_000 < found.soundings < 27_000  # about half the soundings
    median = measure_change([survey], wide, MODEL)  # no cells told: where it states at most its median
    assert median.cells == "at most the median std" and median.std == pytest.approx(found.std, rel=0.05)


def test_the_reference_tracks_error_and_the_datums_drift_are_not_change():
    """The later survey's soundings are placed at a reference track 2 m off, on a map of slope
    0.1, and its depths' offset drifts by 0.3 m over 300 s: stated (``position_std``, the model's
    drift), neither is taken for a change of the seafloor."""
    rng = np.random.default_rng(7)
    tilted = lambda north, east: seafloor(north, east) + 0.1 * east  # noqa: E731
    survey = line_survey(tilted, rng, lines=np.arange(30.0, 380.0, 45.0), name="tilted")
    nn, ee = np.meshgrid(AXIS_MAP_N, AXIS_MAP_E, indexing="ij")
    earlier = BathymetryMap(AXIS_MAP_N, AXIS_MAP_E, tilted(nn, ee), depth_std=np.full(nn.shape, MAP_STD))
    error = field_on_lines(MAP_STD, MAP_LENGTH, rng)
    north, east = survey.footprints(survey.true_pose)
    drift = np.zeros(survey.time.size)
    for k in range(1, drift.size):  # a Gauss-Markov drift, 0.3 m forgetting over 300 s
        keep = np.exp(-1 / 300)
        drift[k] = drift[k - 1] * keep + 0.3 * np.sqrt(1 - keep**2) * rng.standard_normal()
    off = survey.replace(true_pose=survey.true_pose + np.array([0.0, 2.0, 0.0]),
                         beam_depth=survey.beam_depth + error.depth_at(north, east) + drift[:, None])
    told = MODEL.replace(tide_drift_std=0.3, tide_drift_time=300.0)
    found = measure_change([off], earlier, told, position_std=2.0)
    assert found.std < 0.08
    careless = measure_change([off], earlier, MODEL)
    assert careless.std > 0.15 and careless.window_z > 2.0 * found.window_z
