"""Maps gridded from surveys (tangraph.gridding_surveys): a simulated survey reproduces its map,
surveys with other origins and CRSs land in one frame, mixed vertical datums and frames are
refused, a survey without a reference track needs use_dr, and the positioning std must be a
length."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.gridding_surveys import grid_surveys
from tests.gridding_cases import (
    CRS,
    SIGMA,
    _plane_survey,
    nadir_survey,
    random_soundings,
    simulated_survey,
    smooth_map,
)


def gridding_error(bathymetry, grid, min_count=5):
    nn, ee = np.meshgrid(grid.mean.north, grid.mean.east, indexing="ij")
    ok = grid.count >= min_count
    return (grid.depth.depth - bathymetry.depth_at(nn, ee))[ok], grid.count[ok]


@pytest.mark.parametrize("outliers", [False, True])
def test_a_survey_gridded_from_its_truth_reproduces_its_map(outliers):
    m = smooth_map()
    s = simulated_survey(m, **({"outlier_rate": 0.05, "outlier_std": 10.0} if outliers else {}))
    g = grid_surveys([s], cell=5.0)
    assert g.mean.crs == m.crs and g.mean.origin == m.origin and g.statistic == "median"
    assert np.all(np.isin(g.mean.north, m.north)) and np.all(np.isin(g.mean.east, m.east))
    err, count = gridding_error(m, g)
    # The median of n soundings with noise sigma has std 1.2533 sigma / sqrt(n), and the
    # median |error| of a normal error is 0.6745 std. The terrain's change within a cell
    # (slope <= 0.03 on 5 m cells) adds ~0.01 m at the soundings' centroid; 30 % margin
    # covers it and the sampling of the median over ~1000 cells (a few %), and 5 % outliers.
    expected = 0.6745 * 1.2533 * SIGMA * np.median(1 / np.sqrt(count))
    assert np.median(np.abs(err)) < 1.3 * expected
    if outliers:  # the mean is not robust to them
        err_mean, _ = gridding_error(m, grid_surveys([s], cell=5.0, statistic="mean"))
        assert np.median(np.abs(err_mean)) > 1.5 * np.median(np.abs(err))


def test_two_surveys_with_different_origins_land_in_one_frame():
    pts = random_soundings()
    a = nadir_survey(pts, origin=(5.8e6, 4.0e5))
    shift = np.array([100.0, -50.0, 0.0])  # b's origin is 100 m north, 50 m west of a's
    b = nadir_survey(pts - shift, origin=(5.8e6 + 100, 4.0e5 - 50), start=1e5)  # a later survey of them
    one = grid_surveys([a], cell=10.0)
    both = grid_surveys([a, b], cell=10.0, names=["a.nc", "b.nc"])
    np.testing.assert_array_equal(both.mean.north, one.mean.north)
    np.testing.assert_array_equal(both.mean.east, one.mean.east)
    np.testing.assert_array_equal(both.count, 2 * one.count)
    np.testing.assert_allclose(both.median, one.median, rtol=1e-12)
    assert both.mean.origin == (5.8e6, 4.0e5) and both.meta["sources"] == ["a.nc", "b.nc"]
    # in b's frame the same map, shifted by the origins' difference
    flipped = grid_surveys([b, a], cell=10.0)
    np.testing.assert_allclose(flipped.mean.north, one.mean.north - 100.0)
    np.testing.assert_array_equal(flipped.count, both.count)


def test_a_survey_in_another_crs_is_reprojected():
    import pyproj

    pts = random_soundings(seed=1)
    origin = (5.8e6, 4.0e5)
    a = nadir_survey(pts, origin=origin)
    to_other = pyproj.Transformer.from_crs(CRS, "EPSG:25832", always_xy=True)  # the UTM zone west
    x, y = to_other.transform(pts[:, 1] + origin[1], pts[:, 0] + origin[0])
    other_origin = (float(np.floor(y.min())), float(np.floor(x.min())))
    b = nadir_survey(np.column_stack([y - other_origin[0], x - other_origin[1], pts[:, 2]]),
                     origin=other_origin, crs="EPSG:25832", start=1e5)
    one = grid_surveys([a], cell=10.0)
    both = grid_surveys([a, b], cell=10.0)
    np.testing.assert_array_equal(both.count, 2 * one.count)
    assert both.mean.crs == CRS


def test_mixed_vertical_datums_and_frames_are_refused():
    pts = random_soundings(n=200)
    surface = nadir_survey(pts, origin=(0, 0))  # no key: water surface
    level = nadir_survey(pts, origin=(0, 0), datum="water level file zero: LEVEL.csv", start=1e5)
    with pytest.raises(TangraphError, match=r"vertical datums: a\.nc 'water surface', b\.nc 'water level"):
        grid_surveys([surface, level], cell=10.0, names=["a.nc", "b.nc"])
    explicit = nadir_survey(pts, origin=(0, 0), datum="water surface", start=1e5)
    assert grid_surveys([surface, explicit], cell=10.0).meta["vertical_datum"] == "water surface"
    nowhere = nadir_survey(pts, origin=(0, 0), crs=None, start=1e5)
    with pytest.raises(TangraphError, match=r"a\.nc has CRS 'EPSG:32633', b\.nc has None"):
        grid_surveys([surface, nowhere], cell=10.0, names=["a.nc", "b.nc"])


def test_a_survey_without_a_reference_track_needs_use_dr():
    pts = random_soundings(n=200)
    s = nadir_survey(pts, origin=(0, 0), truth=False)
    with pytest.raises(TangraphError, match=r"^dr\.nc: the survey has no reference track"):
        grid_surveys([s], cell=10.0, names=["dr.nc"])
    g = grid_surveys([s], cell=10.0, use_dr=True)
    assert g.meta["track"] == "dr_pose"
    assert g.mean.north[0] == pytest.approx(np.rint((pts[:, 0].min() + 3) / 10) * 10)


def test_the_positioning_std_must_be_a_length():
    from tangraph.maps import grid_surveys

    for bad in (-1.0, float("nan"), True, "3"):
        with pytest.raises(TangraphError, match="position_std must be a number of metres >= 0"):
            grid_surveys(_plane_survey(0.0, n_lines=2), cell=10.0, position_std=bad)


def test_a_survey_given_twice_is_refused_even_in_another_frame():
    pts = random_soundings(n=300)
    a = nadir_survey(pts, origin=(5.8e6, 4.0e5))
    moved = nadir_survey(pts - np.array([100.0, -50.0, 0.0]), origin=(5.8e6 + 100, 4.0e5 - 50))
    for twice in ([a, a], [a, moved]):
        with pytest.raises(TangraphError, match=r"grid_surveys: a\.nc and b\.nc hold the same 300 pings "
                                                "\\(their times and depths\\): a survey given twice"):
            grid_surveys(twice, cell=10.0, names=["a.nc", "b.nc"])
    # two surveys of a flat seafloor at the same times are two surveys: nothing tells them apart
    flat = pts.copy()
    flat[:, 2] = 30.0
    assert grid_surveys([nadir_survey(flat, origin=(0, 0)), nadir_survey(flat, origin=(0, 0))],
                        cell=10.0).count.sum() == 600
