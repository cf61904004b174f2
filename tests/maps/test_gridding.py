"""Gridding soundings (tangraph.maps.gridding): the block reduce against a slow reference, gap
filling, and ``grid_soundings`` on hand-made soundings, point clouds and a loop over cells, with
its refusals."""

from __future__ import annotations

import statistics

import numpy as np
import open3d as o3d
import pytest

from tangraph.errors import TangraphError
from tangraph.maps.gridding import SoundingGrid, block_reduce, fill_gaps, grid_soundings


# -- block reduce against a slow reference -----------------------------------------------------
def weighted_median(z: list[float], w: list[float]) -> float:
    """The documented definition, one cell at a time."""
    pairs = sorted(zip(z, w, strict=True))
    total = sum(w)
    cum = 0.0
    for k, (value, weight) in enumerate(pairs):
        cum += weight
        if cum == total / 2:
            return 0.5 * (value + pairs[k + 1][0])
        if cum > total / 2:
            return value
    raise AssertionError("unreachable")


def reference(pts, cell, weights):
    """Per-cell statistics by a Python loop over the soundings, keyed by (i, j)."""
    cells: dict[tuple[int, int], tuple[list[float], list[float]]] = {}
    n0, e0 = pts[:, 0].min(), pts[:, 1].min()
    for (n, e, z), w in zip(pts, weights, strict=True):
        key = (round((n - n0) / cell), round((e - e0) / cell))
        cells.setdefault(key, ([], []))[0].append(z)
        cells[key][1].append(w)
    out = {}
    for key, (z, w) in cells.items():
        total = sum(w)
        mean = sum(a * b for a, b in zip(z, w, strict=True)) / total
        n = len(z)
        spread = sum(b * (a - mean) ** 2 for a, b in zip(z, w, strict=True))
        var = spread / total * n / (n - 1) if n > 1 else np.nan
        out[key] = (n, mean, weighted_median(z, w), np.sqrt(var))
    return out


@pytest.mark.parametrize("weighted", [False, True])
def test_block_reduce_matches_a_python_reference(weighted):
    rng = np.random.default_rng(11)
    n = 2500
    # depths on a 0.5 m step make ties; integer weights make cumulative weights hit W/2 exactly
    pts = np.column_stack([rng.uniform(-7, 31, n), rng.uniform(200, 222, n),
                           np.round(rng.normal(40, 2, n) * 2) / 2])
    weights = rng.integers(1, 4, n).astype(float) if weighted else np.ones(n)
    g = block_reduce(pts, cell=3.0, weights=weights if weighted else None, statistic="median")
    ref = reference(pts, 3.0, weights)
    assert int(g.count.sum()) == n and np.count_nonzero(g.count) == len(ref)
    for (i, j), (count, mean, median, std) in ref.items():
        assert g.count[i, j] == count
        np.testing.assert_allclose(g.mean.depth[i, j], mean, rtol=1e-12)
        assert g.median[i, j] == median
        np.testing.assert_allclose(g.std[i, j], std, rtol=1e-9)
    np.testing.assert_array_equal(g.depth.depth, g.median)


def test_unweighted_median_is_the_ordinary_median_with_real_weights_too():
    rng = np.random.default_rng(2)
    pts = np.column_stack([rng.uniform(0, 10, 400), rng.uniform(0, 10, 400), rng.normal(0, 1, 400)])
    g = block_reduce(pts, cell=5.0)
    i = np.rint(pts[:, 0] / 5 - pts[:, 0].min() / 5).astype(int)
    j = np.rint(pts[:, 1] / 5 - pts[:, 1].min() / 5).astype(int)
    z = pts[(i == 1) & (j == 1), 2]
    assert g.median[1, 1] == statistics.median(z.tolist())
    w = rng.uniform(0.1, 3.0, 400)  # real weights: the cumulative weight never hits W/2
    gw = block_reduce(pts, cell=5.0, weights=w)
    sel = (i == 1) & (j == 1)
    assert gw.median[1, 1] == weighted_median(pts[sel, 2].tolist(), w[sel].tolist())
    np.testing.assert_allclose(gw.mean.depth[1, 1], np.average(pts[sel, 2], weights=w[sel]), rtol=1e-12)


def test_block_reduce_drops_nan_rows_and_refuses_bad_weights():
    pts = np.array([[0.0, 0, 10], [1, 1, np.nan], [np.nan, 0, 3], [1, 1, 12]])
    g = block_reduce(pts, cell=1.0)
    assert g.n_dropped == 2 and g.count.sum() == 2
    with pytest.raises(TangraphError, match="positive"):
        block_reduce(pts, cell=1.0, weights=[1, 1, 1, 0])
    with pytest.raises(TangraphError, match="shape"):
        block_reduce(pts, cell=1.0, weights=[1, 1])


def test_a_grid_too_large_for_memory_is_refused_before_it_is_made():
    # soundings of two areas 16 000 km apart (another CRS), or a cell far finer than the data
    far = np.array([[0.0, 0.0, 10.0], [16e6, 4e6, 12.0]])
    with pytest.raises(TangraphError, match=r"soundings 'far': a grid of 3,200,001 x 800,001 cells of 5 m "
                                            r"over 16,000.0 x 4,000.0 km is too large \(at most 100,000,000 "
                                            r"cells\): use a larger cell, or soundings of one area"):
        block_reduce(far, cell=5.0, name="far")
    with pytest.raises(TangraphError, match="a grid of 10,001 x 10,001 cells of 0.01 m"):
        block_reduce(np.array([[0.0, 0.0, 10.0], [100.0, 100.0, 12.0]]), cell=0.01)


# -- gap filling -------------------------------------------------------------------------------
def test_fill_gaps_fills_a_one_cell_hole_and_leaves_far_cells_nan():
    nn, ee = np.meshgrid(np.arange(9.0), np.arange(12.0), indexing="ij")
    depth = 50 + nn + 2 * ee
    keep = ~((nn == 4) & (ee == 3))  # a hole of one cell
    keep &= ~((nn >= 2) & (nn <= 6) & (ee >= 7) & (ee <= 11))  # a big empty block at the edge
    pts = np.column_stack([nn[keep], ee[keep], depth[keep]])
    g = block_reduce(pts, cell=1.0)
    assert np.isnan(g.depth.depth[4, 3])
    f = fill_gaps(g, 1)
    # the four neighbours of a plane average to its value at the hole
    assert f.depth.depth[4, 3] == pytest.approx(50 + 4 + 6)
    block = f.depth.depth[2:7, 7:]
    assert np.all(np.isfinite(block[:, 0]))  # one cell from data: filled
    assert np.all(np.isnan(block[1:-1, 1:]))  # farther: no data
    assert f.n_filled == 1 + 5 + 2 * 4  # the hole, the block's west column, its north and south rows
    np.testing.assert_array_equal(f.count, g.count)  # the soundings' layers are untouched
    assert np.isnan(f.mean.depth[4, 3]) and f.meta["gap_fill"]["cells"] == 1
    # a radius beyond the grid's diagonal (15 cells) fills what the diagonal does, at its cost
    wide, huge = fill_gaps(g, 15), fill_gaps(g, 10**6)
    np.testing.assert_array_equal(huge.depth.depth, wide.depth.depth)
    assert huge.meta["gap_fill"]["cells"] == 15 and np.all(np.isfinite(huge.depth.depth))
    assert fill_gaps(g, 0).n_filled == 0
    with pytest.raises(TangraphError, match="integer"):
        fill_gaps(g, -1)


def test_a_gap_between_lines_on_a_slope_is_filled_with_the_slope():
    # two survey strips (columns 0-2 and 9-11) of a plane sloping across them: the gap between
    # is filled by the plane exactly, where an inverse distance average would lean on the
    # nearer strip (a sawtooth across the gap, the same along it)
    nn, ee = np.meshgrid(np.arange(20.0), np.arange(12.0), indexing="ij")
    depth = 50 + 0.1 * nn + 0.5 * ee
    keep = (ee <= 2) | (ee >= 9)
    g = block_reduce(np.column_stack([nn[keep], ee[keep], depth[keep]]), cell=1.0)
    f = fill_gaps(g, 3)
    gap = np.s_[:, 3:9]
    np.testing.assert_allclose(f.depth.depth[gap], depth[gap], atol=1e-9)
    assert "linear" in f.meta["gap_fill"]["method"]
    # a gap wider than twice the radius is not bridged: its cells within reach lean on their
    # own side (the depth flattened towards that strip's), the middle stays no-data
    w = fill_gaps(g, 2).depth.depth
    assert np.all(w[2:-2, 3:5] < depth[2:-2, 3:5]) and np.all(w[2:-2, 7:9] > depth[2:-2, 7:9])
    assert np.all(np.isnan(w[:, 5:7]))


# -- soundings ---------------------------------------------------------------------------------
SOUNDINGS = np.array(
    [
        [0.0, 0.0, 10.0],
        [0.3, 0.2, 12.0],
        [0.4, 0.1, 14.0],
        [0.1, 1.9, 20.0],
        [2.0, 1.0, 30.0],
        [1.6, 1.4, 34.0],
        [np.nan, 1.0, 5.0],
        [1.0, 1.0, np.nan],
    ]
)


def check_hand_made(g: SoundingGrid, n_dropped: int = 2):
    np.testing.assert_array_equal(g.count, [[3, 0, 1], [0, 0, 0], [0, 2, 0]])
    nan = np.nan
    np.testing.assert_allclose(
        g.mean.depth, [[12, nan, 20], [nan, nan, nan], [nan, 32, nan]], rtol=1e-15
    )
    np.testing.assert_allclose(
        g.std, [[2, nan, nan], [nan, nan, nan], [nan, np.sqrt(8), nan]], rtol=1e-15
    )
    np.testing.assert_array_equal(g.mean.north, [0, 1, 2])
    np.testing.assert_array_equal(g.mean.east, [0, 1, 2])
    assert g.n_dropped == n_dropped


def test_grid_soundings_hand_made():
    g = grid_soundings(SOUNDINGS, cell=1.0, name="mb")
    check_hand_made(g)
    assert g.mean.name == "mb"
    assert not g.count.flags.writeable


def test_grid_soundings_point_cloud_same_as_array():
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(SOUNDINGS))
    check_hand_made(grid_soundings(pcd, cell=1.0))


def test_grid_soundings_extent_drops_points_outside():
    g = grid_soundings(SOUNDINGS, cell=1.0, extent=(0.0, 1.0, 0.0, 2.0))
    np.testing.assert_array_equal(g.count, [[3, 0, 1], [0, 0, 0]])
    assert g.n_dropped == 4


def test_grid_soundings_matches_a_loop_over_cells():
    rng = np.random.default_rng(3)
    pts = np.column_stack(
        [rng.uniform(-5, 20, 3000), rng.uniform(100, 112, 3000), rng.normal(40, 2, 3000)]
    )
    g = grid_soundings(pts, cell=2.5)
    i = np.rint((pts[:, 0] - pts[:, 0].min()) / 2.5).astype(int)
    j = np.rint((pts[:, 1] - pts[:, 1].min()) / 2.5).astype(int)
    assert g.count.sum() == 3000
    for a, b in [(0, 0), (3, 2), (10, 4), (5, 1)]:
        z = pts[(i == a) & (j == b), 2]
        assert g.count[a, b] == z.size
        np.testing.assert_allclose(g.mean.depth[a, b], z.mean(), rtol=1e-12)
        np.testing.assert_allclose(g.std[a, b], z.std(ddof=1), rtol=1e-9)


def test_grid_soundings_rejects_bad_input():
    with pytest.raises(TangraphError, match=r"points must have shape \(N, 3\)"):
        grid_soundings(np.zeros((4, 2)), cell=1.0)
    with pytest.raises(TangraphError, match="no finite soundings"):
        grid_soundings(np.full((3, 3), np.nan), cell=1.0)
    with pytest.raises(TangraphError, match="cell must be"):
        grid_soundings(SOUNDINGS, cell=-1.0)
    with pytest.raises(TangraphError, match="north spans"):
        grid_soundings([[0.0, 0, 1], [0.1, 5, 1]], cell=1.0)
    with pytest.raises(TangraphError, match="extent"):
        grid_soundings(SOUNDINGS, cell=1.0, extent=(2.0, 1.0, 0.0, 1.0))
