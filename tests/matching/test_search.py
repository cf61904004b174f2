"""The TAP criterion search: both fast paths against a slow numpy reference, known answers,
invalid candidates, memory refusal and bad input."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap
from tangraph.matching.search import CandidateGrid, CriterionSums, criterion_sums
from tests.maps.reference import interpolate

DN, DE = 5.0, 4.0  # unequal cells catch north/east mix-ups
FIELDS = ("sum_d", "sum_d2", "sum_abs", "sum_h", "sum_h2", "sum_hz")


def rough_map(seed=0, shape=(70, 80), nan_block=True):
    rng = np.random.default_rng(seed)
    depth = 60 + np.cumsum(np.cumsum(rng.normal(size=shape), axis=0), axis=1) * 0.05
    depth += 3 * np.sin(np.arange(shape[0])[:, None] / 4.0) * np.cos(np.arange(shape[1]) / 5.0)
    if nan_block:
        depth[30:33, 50:52] = np.nan
    return BathymetryMap(north=-100 + DN * np.arange(shape[0]), east=20 + DE * np.arange(shape[1]),
                         depth=depth, name="rough")  # fmt: skip


def swath(rng, n=40, spread=25.0):
    """Offsets of a small patch, off the cell lines (random, not on nodes)."""
    return rng.uniform(-spread, spread, (n, 2))


def rotate(offsets, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.column_stack([c * offsets[:, 0] - s * offsets[:, 1], s * offsets[:, 0] + c * offsets[:, 1]])


def sample(m, position, offsets, tide=0.0, angle=0.0):
    off = rotate(offsets, angle)
    return m.depth_at(position[0] + off[:, 0], position[1] + off[:, 1]) + tide


def reference_sums(m, offsets, depths, grid):
    """The slow reference: a loop over candidates, numpy over soundings."""
    keep = np.isfinite(depths)
    offsets, z = offsets[keep], depths[keep]
    out = {k: np.full(grid.shape, np.nan) for k in FIELDS}
    count = np.zeros(grid.shape, dtype=int)
    for k, angle in enumerate(grid.headings):
        off = rotate(offsets, angle)
        for i, north in enumerate(grid.north):
            for j, east in enumerate(grid.east):
                h, _ = interpolate(m.north, m.east, m.depth, north + off[:, 0], east + off[:, 1], 1, False)
                count[k, i, j] = np.isfinite(h).sum()
                if count[k, i, j] == z.size:
                    d = h - z
                    values = (d.sum(), d @ d, np.abs(d).sum(), h.sum(), h @ h, h @ z)
                    for name, value in zip(FIELDS, values, strict=True):
                        out[name][k, i, j] = value
    return count, out


def grid_on_cells(m, centre_cell=(35, 40), half=(7, 8), steps=(1, 1), headings=(0.0,)):
    """A candidate grid whose steps are whole numbers of cells, candidates off the cell centres."""
    i, j = centre_cell
    north = m.north[i] + 1.3 + DN * steps[0] * np.arange(-half[0], half[0] + 1)
    east = m.east[j] - 0.7 + DE * steps[1] * np.arange(-half[1], half[1] + 1)
    return CandidateGrid(north, east, np.asarray(headings))


def assert_matches(sums, count, ref, *, rtol, d2_atol):
    np.testing.assert_array_equal(sums.count, count)
    np.testing.assert_array_equal(sums.valid, count == sums.n_soundings)
    for name in FIELDS:
        got = getattr(sums, name)
        if name == "sum_abs" and sums.method == "fft":
            assert np.all(np.isnan(got))
            continue
        np.testing.assert_array_equal(np.isnan(got), np.isnan(ref[name]), err_msg=name)
        atol = d2_atol if name == "sum_d2" else rtol * np.nanmax(np.abs(ref["sum_h"]))
        np.testing.assert_allclose(got, ref[name], rtol=rtol, atol=atol, err_msg=name)


def fft_d2_tolerance(m, z):
    """Stated accuracy of the FFT path: 1e-14 N max|depth - mean z|^2 over the window."""
    return 1e-14 * z.size * np.nanmax(np.abs(m.depth - z.mean())) ** 2


# -- both fast paths against the reference --------------------------------------------------------
GRIDS = {
    "whole cells": {},
    "2 x 3 cells": {"half": (4, 3), "steps": (2, 3)},
    "whole cells, 3 headings": {"half": (4, 5), "headings": (-0.2, 0.0, 0.15)},
    "off the map and next to NaN": {"centre_cell": (40, 62), "half": (9, 14)},
    "one candidate": {"half": (0, 0)},
    "one candidate row": {"half": (0, 6)},
}


@pytest.mark.parametrize("case", GRIDS)
@pytest.mark.parametrize("method", ["direct", "fft"])
def test_whole_cell_paths_match_the_reference(case, method):
    m = rough_map()
    rng = np.random.default_rng(1)
    offsets = swath(rng)
    depths = sample(m, (m.north[35] + 2.0, m.east[40] + 1.0), offsets, tide=0.4) + rng.normal(0, 0.2, 40)
    grid = grid_on_cells(m, **GRIDS[case])
    sums = criterion_sums(m, offsets, depths, grid, method=method)
    count, ref = reference_sums(m, offsets, depths, grid)
    assert sums.method == method
    d2_atol = 1e-9 * np.nanmax(ref["sum_d2"]) if method == "direct" else fft_d2_tolerance(m, depths)
    assert_matches(sums, count, ref, rtol=1e-9 if method == "direct" else 1e-12, d2_atol=d2_atol)
    if case.startswith("off"):
        assert 0 < sums.valid.sum() < sums.grid.size  # the case does hold both kinds
        assert np.any((count > 0) & (count < offsets.shape[0]))


@pytest.mark.parametrize("headings", [(0.0,), (-0.3, 0.1)])
def test_general_direct_path_matches_the_reference(headings):
    m = rough_map()
    rng = np.random.default_rng(2)
    offsets = swath(rng)
    depths = sample(m, (40.0, 180.0), offsets) + rng.normal(0, 0.3, 40)
    grid = CandidateGrid.around((41.1, 178.3), 60.0, 3.3, headings)  # sub-cell step; reaches the NaN block
    sums = criterion_sums(m, offsets, depths, grid)
    count, ref = reference_sums(m, offsets, depths, grid)
    assert sums.method == "direct"
    assert_matches(sums, count, ref, rtol=1e-9, d2_atol=1e-9 * np.nanmax(ref["sum_d2"]))
    assert 0 < sums.valid.sum() < sums.grid.size


@pytest.mark.parametrize(("method", "step"), [("direct", DE), ("fft", DE), ("direct", 0.9 * DE)])
def test_wide_grids_span_several_tiles_and_a_partial_block(method, step):
    m = rough_map(shape=(60, 400))
    rng = np.random.default_rng(9)
    offsets = swath(rng, n=13, spread=10.0)  # one full block of 8 soundings and a partial one
    depths = sample(m, (50.0, 800.0), offsets) + rng.normal(0, 0.1, 13)
    grid = CandidateGrid(north=50.3 + DN * np.arange(-7, 8), east=2.1 + step * np.arange(1, 380))
    sums = criterion_sums(m, offsets, depths, grid, method=method)
    count, ref = reference_sums(m, offsets, depths, grid)
    d2_atol = 1e-9 * np.nanmax(ref["sum_d2"]) if method == "direct" else fft_d2_tolerance(m, depths)
    assert_matches(sums, count, ref, rtol=1e-9, d2_atol=d2_atol)
    assert 0 < sums.valid.sum() < sums.grid.size


def test_derived_criteria_follow_from_the_residuals():
    m = rough_map(nan_block=False)
    rng = np.random.default_rng(3)
    offsets = swath(rng, n=30)
    depths = sample(m, (30.0, 150.0), offsets, tide=-1.2) + rng.normal(0, 0.5, 30)
    grid = CandidateGrid.around((30.0, 150.0), 20.0, 2.5)
    sums = criterion_sums(m, offsets, depths, grid, method="direct")
    k, i, j = 0, 3, 11
    h = sample(m, (grid.north[i], grid.east[j]), offsets)
    d = h - depths
    t = d.mean()
    assert sums.tide()[k, i, j] == pytest.approx(t, rel=1e-10)
    assert sums.msd()[k, i, j] == pytest.approx(np.mean(d**2), rel=1e-10)
    assert sums.mad()[k, i, j] == pytest.approx(np.mean(np.abs(d)), rel=1e-10)
    assert sums.sigma2()[k, i, j] == pytest.approx(np.var(d, ddof=1), rel=1e-9)
    assert sums.rss_fixed_tide(0.3)[k, i, j] == pytest.approx(np.sum((d - 0.3) ** 2), rel=1e-10)
    assert sums.correlation()[k, i, j] == pytest.approx(np.corrcoef(h, depths)[0, 1], rel=1e-9)


# -- known answers --------------------------------------------------------------------------------
@pytest.mark.parametrize("method", ["direct", "fft"])
@pytest.mark.parametrize("tide", [0.0, 2.5])
def test_soundings_from_the_map_are_found_at_the_truth(method, tide):
    m = rough_map(nan_block=False)
    rng = np.random.default_rng(4)
    offsets = swath(rng, n=60, spread=30.0)
    grid = grid_on_cells(m, half=(8, 8))
    truth = (5, 11)  # indices into grid.north, grid.east: on the candidate grid
    depths = sample(m, (grid.north[truth[0]], grid.east[truth[1]]), offsets, tide=tide)
    sums = criterion_sums(m, offsets, depths, grid, method=method)
    at = (0, *truth)
    atol = 1e-18 if method == "direct" else fft_d2_tolerance(m, depths)
    atol += 1e-15 * depths.size * tide**2  # sum_d2 - n t^2 cancels at the scale of the tide
    assert sums.sigma2()[at] == pytest.approx(0.0, abs=atol)
    assert sums.tide()[at] == pytest.approx(-tide, abs=1e-12)
    assert sums.rss_fixed_tide(-tide)[at] == pytest.approx(0.0, abs=atol)
    if tide == 0.0:
        assert sums.sum_d2[at] == pytest.approx(0.0, abs=atol)
        assert np.unravel_index(np.nanargmin(sums.msd()), grid.shape) == at
    assert np.unravel_index(np.nanargmin(sums.sigma2()), grid.shape) == at
    assert np.unravel_index(np.nanargmax(sums.correlation()), grid.shape) == at
    assert sums.correlation()[at] == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("method", ["direct", "fft"])
def test_heading_search_recovers_a_rotated_patch(method):
    m = rough_map(nan_block=False)
    rng = np.random.default_rng(5)
    offsets = swath(rng, n=80, spread=35.0)
    headings = np.radians([-6.0, -3.0, 0.0, 3.0, 6.0])
    grid = grid_on_cells(m, half=(5, 5), headings=headings)
    truth = (2, 7)
    depths = sample(m, (grid.north[truth[0]], grid.east[truth[1]]), offsets, tide=1.0, angle=headings[3])
    sums = criterion_sums(m, offsets, depths, grid, method=method)
    assert np.unravel_index(np.nanargmin(sums.sigma2()), grid.shape) == (3, *truth)
    assert sums.tide()[3, *truth] == pytest.approx(-1.0, abs=1e-9)


def test_invalid_candidates_are_marked_alike_by_all_paths():
    m = rough_map()
    rng = np.random.default_rng(6)
    offsets = swath(rng, n=25, spread=12.0)
    depths = sample(m, (55.0, 230.0), offsets)
    grid = grid_on_cells(m, centre_cell=(31, 51), half=(10, 12))  # the NaN block and the map's edge
    direct = criterion_sums(m, offsets, depths, grid, method="direct")
    fft = criterion_sums(m, offsets, depths, grid, method="fft")
    count, _ = reference_sums(m, offsets, depths, grid)
    for sums in (direct, fft):
        np.testing.assert_array_equal(sums.count, count)
        assert np.all(np.isnan(sums.sum_d2[~sums.valid])) and np.all(np.isnan(sums.sigma2()[~sums.valid]))
        assert np.all(np.isfinite(sums.sum_d2[sums.valid]))
    assert 0 < direct.valid.sum() < grid.size
    assert np.all(count[~direct.valid] < offsets.shape[0])


def test_nan_soundings_are_dropped_first():
    m = rough_map(nan_block=False)
    rng = np.random.default_rng(7)
    offsets = swath(rng, n=20)
    depths = sample(m, (20.0, 150.0), offsets)
    holed = depths.copy()
    holed[[2, 9]] = np.nan
    grid = CandidateGrid.around((20.0, 150.0), 12.0, 4.0)
    a = criterion_sums(m, offsets, holed, grid)
    b = criterion_sums(m, np.delete(offsets, [2, 9], axis=0), np.delete(depths, [2, 9]), grid)
    assert a.n_soundings == 18
    np.testing.assert_array_equal(a.sum_d2, b.sum_d2)


def test_auto_picks_fft_for_large_whole_cell_searches_and_direct_otherwise():
    rng = np.random.default_rng(8)
    m = BathymetryMap(north=np.arange(400) * 5.0, east=np.arange(400) * 5.0,
                      depth=80 + rng.normal(size=(400, 400)).cumsum(axis=0) * 0.1)  # fmt: skip
    offsets = swath(rng, n=600, spread=60.0)
    depths = sample(m, (1000.0, 1000.0), offsets)
    large, small, sub_cell = (CandidateGrid.around((1000.0, 1000.0), w, s) for w, s in
                              ((500.0, 5.0), (10.0, 5.0), (40.0, 2.5)))  # fmt: skip
    assert criterion_sums(m, offsets, depths, large).method == "fft"
    assert criterion_sums(m, offsets, depths, small).method == "direct"
    assert criterion_sums(m, offsets[:5], depths[:5], large).method == "direct"
    assert criterion_sums(m, offsets, depths, sub_cell).method == "direct"


def test_degenerate_patches_give_nan_criteria_without_warnings():
    m = rough_map(nan_block=False)
    grid = CandidateGrid.around((20.0, 150.0), 8.0, 4.0)
    one = criterion_sums(m, np.zeros((1, 2)), np.array([60.0]), grid)
    assert np.all(np.isnan(one.sigma2())) and np.all(np.isfinite(one.msd()))
    flat = criterion_sums(m, np.array([[0.0, 0.0], [3.0, 1.0]]), np.array([60.0, 60.0]), grid)
    assert np.all(np.isnan(flat.correlation()))


def test_grid_and_results_are_frozen():
    grid = CandidateGrid.around((0.0, 0.0), 10.0, 5.0, headings=[0.0, 0.1])
    assert grid.shape == (2, 5, 5) and grid.size == 50 and grid.nbytes_needed() > 50 * 7 * 8
    np.testing.assert_array_equal(grid.north, [-10.0, -5.0, 0.0, 5.0, 10.0])
    with pytest.raises(ValueError, match="read-only"):
        grid.north[0] = 1.0
    m = rough_map(nan_block=False)
    grid = CandidateGrid.around((20.0, 150.0), 8.0, 4.0)
    sums = criterion_sums(m, np.zeros((2, 2)), np.array([60.0, 61.0]), grid)
    assert isinstance(sums, CriterionSums)
    with pytest.raises(ValueError, match="read-only"):
        sums.sum_d2[0, 0, 0] = 1.0


# -- refusals and bad input -----------------------------------------------------------------------
def test_a_search_larger_than_max_bytes_is_refused_naming_its_size():
    m = rough_map()
    grid = CandidateGrid.around((50.0, 150.0), 100.0, 1.0, headings=np.linspace(-0.1, 0.1, 5))
    with pytest.raises(TangraphError, match=r"would need about \d+ MB.*max_bytes"):
        criterion_sums(m, np.zeros((3, 2)), np.full(3, 60.0), grid, max_bytes=1e6)


@pytest.mark.parametrize(
    ("offsets", "depths", "match"),
    [
        (np.zeros((4, 3)), np.zeros(4), "must be"),
        (np.zeros((4, 2)), np.zeros(5), "must be"),
        (np.array([[0.0, np.nan], [1.0, 1.0]]), np.zeros(2), "not finite"),
        (np.zeros((2, 2)), np.array([60.0, np.inf]), "infinite"),
        (np.zeros((2, 2)), np.full(2, np.nan), "no soundings"),
        (np.zeros((0, 2)), np.zeros(0), "no soundings"),
    ],
)
def test_bad_patches_are_refused(offsets, depths, match):
    with pytest.raises(TangraphError, match=match):
        criterion_sums(rough_map(), offsets, depths, CandidateGrid.around((50.0, 150.0), 10.0, 5.0))


def test_bad_methods_and_grids_are_refused():
    m = rough_map()
    off, z = np.zeros((2, 2)), np.array([60.0, 61.0])
    with pytest.raises(TangraphError, match="whole map cells"):
        criterion_sums(m, off, z, CandidateGrid.around((50.0, 150.0), 10.0, 3.0), method="fft")
    with pytest.raises(TangraphError, match="method"):
        criterion_sums(m, off, z, CandidateGrid.around((50.0, 150.0), 10.0, 5.0), method="fast")
    with pytest.raises(TangraphError, match="BathymetryMap"):
        criterion_sums(m.depth, off, z, CandidateGrid.around((50.0, 150.0), 10.0, 5.0))
    for north in ([], [0.0, np.nan], [2.0, 1.0], [0.0, 1.0, 3.0], np.zeros((2, 2))):
        with pytest.raises(TangraphError, match="north"):
            CandidateGrid(north=north, east=[0.0])
    with pytest.raises(TangraphError, match="step"):
        CandidateGrid.around((0.0, 0.0), 10.0, 0.0)
    with pytest.raises(TangraphError, match="centre"):
        CandidateGrid.around((0.0, 0.0, 1.0), 10.0, 1.0)
