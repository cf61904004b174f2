"""Gridding soundings and surveys: the block reduce, gap filling, frames, datums and the CLI."""

from __future__ import annotations

import dataclasses
import json
import statistics

import numpy as np
import pytest
import xarray as xr

from tangraph.cli import main
from tangraph.errors import TangraphError
from tangraph.gridding_files import grid_files
from tangraph.gridding_surveys import grid_surveys
from tangraph.maps import BathymetryMap, read_map
from tangraph.maps.gridding import block_reduce, fill_gaps
from tangraph.sim.scenario import load_scenario, simulate
from tangraph.survey import Survey, read_survey, write_survey

SIGMA = 0.5  # sounding noise (m) of the simulated surveys
CRS = "EPSG:32633"


# -- block reduce against a slow reference ----------------------------------------------------
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


# -- gap filling ------------------------------------------------------------------------------
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
    assert fill_gaps(g, 0).n_filled == 0
    with pytest.raises(TangraphError, match="integer"):
        fill_gaps(g, -1)


# -- a simulated survey reproduces its map ----------------------------------------------------
def smooth_map(cell=5.0) -> BathymetryMap:
    north = east = np.arange(0, 600.0, cell)
    nn, ee = np.meshgrid(north, east, indexing="ij")
    depth = 40 + 2 * np.sin(2 * np.pi * nn / 400) * np.cos(2 * np.pi * ee / 500)
    return BathymetryMap(north, east, depth, crs=CRS, origin=(5.8e6, 4.0e5), name="smooth")


def simulated_survey(bathymetry: BathymetryMap, seed=1, **sonar) -> Survey:
    scenario = load_scenario("han2020")
    quiet = dataclasses.replace(scenario.sonar, ping_rate=1.0, depth_noise=SIGMA, range_noise=0.0,
                                tide=0.0, **sonar)
    scenario = dataclasses.replace(
        scenario, sonar=quiet, vehicle_depth=20.0,
        trajectory={"kind": "lawnmower", "origin": [100.0, 100.0], "heading_deg": 0.0,
                    "line_length": 300.0, "line_spacing": 30.0, "n_lines": 4, "speed": 2.0},
    )
    return simulate(scenario, rng=np.random.default_rng(seed), bathymetry=bathymetry, seed=seed)


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


# -- frames, datums, references ---------------------------------------------------------------
def nadir_survey(points, *, origin, crs=CRS, truth=True, datum=None) -> Survey:
    """A single-beam survey whose soundings lie exactly at its poses."""
    k = len(points)
    pose = np.column_stack([points[:, 0], points[:, 1], np.zeros(k)])
    meta = {"crs": crs, "origin": list(origin)}
    if datum is not None:
        meta["vertical_datum"] = datum
    return Survey(time=np.arange(k, dtype=float), dr_pose=pose + 3.0, vehicle_depth=np.zeros(k),
                  beam_forward=np.zeros((k, 1)), beam_starboard=np.zeros((k, 1)),
                  beam_depth=points[:, 2:3], true_pose=pose if truth else None, meta=meta)


def random_soundings(seed=0, n=3000):
    rng = np.random.default_rng(seed)
    north, east = rng.uniform(0, 200, (2, n))
    return np.column_stack([north, east, 30 + 0.05 * north + rng.normal(0, 0.1, n)])


def test_two_surveys_with_different_origins_land_in_one_frame():
    pts = random_soundings()
    a = nadir_survey(pts, origin=(5.8e6, 4.0e5))
    shift = np.array([100.0, -50.0, 0.0])  # b's origin is 100 m north, 50 m west of a's
    b = nadir_survey(pts - shift, origin=(5.8e6 + 100, 4.0e5 - 50))
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
                     origin=other_origin, crs="EPSG:25832")
    one = grid_surveys([a], cell=10.0)
    both = grid_surveys([a, b], cell=10.0)
    np.testing.assert_array_equal(both.count, 2 * one.count)
    assert both.mean.crs == CRS


def test_mixed_vertical_datums_and_frames_are_refused():
    pts = random_soundings(n=200)
    surface = nadir_survey(pts, origin=(0, 0))  # no key: water surface
    level = nadir_survey(pts, origin=(0, 0), datum="water level file zero: LEVEL.csv")
    with pytest.raises(TangraphError, match=r"vertical datums: a\.nc 'water surface', b\.nc 'water level"):
        grid_surveys([surface, level], cell=10.0, names=["a.nc", "b.nc"])
    explicit = nadir_survey(pts, origin=(0, 0), datum="water surface")
    assert grid_surveys([surface, explicit], cell=10.0).meta["vertical_datum"] == "water surface"
    nowhere = nadir_survey(pts, origin=(0, 0), crs=None)
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


def test_grid_files_names_its_keywords_or_the_callers_options(tmp_path):
    """The library's errors name its keywords; ``tangraph maps grid`` passes its own name and options,
    and its messages are exactly those it always printed."""
    pts = random_soundings(n=300)
    plain = write_survey(nadir_survey(pts, origin=(0, 0)), tmp_path / "plain.nc")
    xyz = tmp_path / "s.xyz"
    np.savetxt(xyz, pts[:, [1, 0, 2]])
    out = tmp_path / "out.nc"
    cli = {"where": "maps grid", "option_name": lambda keyword: "--" + keyword.replace("_", "-")}
    cases = [
        ([plain], {"units": "ft"}, "grid_files: units applies to x y z text; survey files hold depths "
         "(positive down) in their own CRS", "maps grid: --units applies to x y z text; survey files hold "
         "depths (positive down) in their own CRS"),
        ([xyz], {"lines": True}, "grid_files: check_lines and lines need survey files (.nc)",
         "maps grid: --check-lines and --lines need survey files (.nc)"),
        ([xyz], {}, "grid_files: x y z text input needs sign (depth or elevation)",
         "maps grid: x y z text input needs --sign (depth or elevation)"),
        ([xyz], {"sign": "depth", "use_dr": True}, "grid_files: use_dr applies to survey files (.nc), not "
         "x y z text", "maps grid: --use-dr applies to survey files (.nc), not x y z text"),
        ([plain], {"use_dr": True, "check_lines": True}, "grid_files: check_lines compares soundings at "
         "reference tracks; not with use_dr", "maps grid: --check-lines compares soundings at reference "
         "tracks; not with --use-dr"),
        ([plain, xyz], {}, "grid_files: give survey files (.nc) or one x y z text file, not both",
         "maps grid: give survey files (.nc) or one x y z text file, not both"),
        ([plain], {"output": plain}, f"grid_files: the output {plain} is one of the inputs",
         f"maps grid: the output {plain} is one of the inputs"),
    ]
    for inputs, options, library, command in cases:
        options = {"output": out, **options}
        for wording, message in (({}, library), (cli, command)):
            with pytest.raises(TangraphError) as err:
                grid_files(inputs, cell=10.0, **options, **wording)
            assert str(err.value) == message
    grid, check = grid_files([xyz], tmp_path / "xyz.nc", cell=10.0, sign="depth", position_std=0.5)
    assert check is None and grid.mean.name == "xyz" and grid.meta["position_std"] == 0.5


# -- command line ---------------------------------------------------------------------------
def test_cli_grids_surveys_end_to_end(tmp_path, capsys):
    m = smooth_map()
    surveys = [simulated_survey(m, seed=1), simulated_survey(m, seed=2)]
    a = write_survey(surveys[0], tmp_path / "a.nc")
    b = write_survey(surveys[1], tmp_path / "b.nc")
    out = tmp_path / "map.nc"
    assert main(["maps", "grid", str(a), str(b), "--cell", "5", "--fill", "2", "-o", str(out)]) == 0
    line = capsys.readouterr().out.strip()
    assert line.startswith("gridded ") and "median" in line and f"wrote {out}" in line
    assert "\n" not in line and "more filled by --fill 2" in line
    grid = read_map(out)
    assert grid.crs == m.crs and grid.origin == m.origin and grid.cell_size == (5.0, 5.0)
    with xr.open_dataset(out) as ds:
        assert {"depth", "mean", "median", "count", "std", "filled"} <= set(ds.data_vars)
        assert ds["depth"].attrs["cell_methods"] == "area: median"
        meta = json.loads(ds.attrs["tangraph_meta"])
        assert meta["sources"] == [str(a), str(b)] and meta["vertical_datum"] == "water surface"
        assert int(ds["count"].sum()) == sum(s.n_soundings for s in surveys)
        count = ds["count"].values
        measured = count > 0
        np.testing.assert_array_equal(ds["depth"].values[measured], ds["median"].values[measured])
        assert int(ds["filled"].sum()) == int(np.sum(~measured & np.isfinite(ds["depth"].values)))
    nn, ee = np.meshgrid(grid.north, grid.east, indexing="ij")
    ok = count >= 5
    err = (grid.depth - m.depth_at(nn, ee))[ok]
    assert np.median(np.abs(err)) < 1.3 * 0.6745 * 1.2533 * SIGMA * np.median(1 / np.sqrt(count[ok]))
    same = grid_surveys([read_survey(a), read_survey(b)], cell=5.0, fill=2)
    np.testing.assert_array_equal(same.depth.depth, grid.depth)


def test_cli_user_errors_are_one_line_and_status_2(tmp_path, capsys):
    pts = random_soundings(n=300)
    plain = write_survey(nadir_survey(pts, origin=(0, 0)), tmp_path / "plain.nc")
    dr_only = write_survey(nadir_survey(pts, origin=(0, 0), truth=False), tmp_path / "dr.nc")
    level = write_survey(nadir_survey(pts, origin=(0, 0), datum="chart datum"), tmp_path / "level.nc")
    xyz = tmp_path / "s.xyz"
    np.savetxt(xyz, pts[:, [1, 0, 2]])
    out = str(tmp_path / "out.nc")
    cases = [
        ([str(dr_only)], "dr.nc: the survey has no reference track"),
        ([str(plain), str(level)], "level.nc 'chart datum'"),
        ([str(plain), "--sign", "depth"], "--sign applies to x y z text"),
        ([str(plain), str(xyz), "--sign", "depth"], "not both"),
        ([str(xyz)], "needs --sign"),
        ([str(xyz), "--sign", "depth", "--use-dr"], "--use-dr applies to survey files"),
    ]
    for inputs, message in cases:
        assert main(["maps", "grid", *inputs, "--cell", "10", "-o", out]) == 2, message
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
    assert main(["maps", "grid", str(plain), "--cell", "10", "-o", str(plain), "--force"]) == 2
    assert "is one of the inputs" in capsys.readouterr().err
    assert main(["maps", "grid", str(dr_only), "--cell", "10", "--use-dr", "-o", out]) == 0
    capsys.readouterr()
    out_xyz = str(tmp_path / "xyz.nc")
    assert main(["maps", "grid", str(xyz), "--cell", "10", "--sign", "depth", "--statistic", "mean",
                 "-o", out_xyz]) == 0
    assert "(10 m, mean)" in capsys.readouterr().out
    with xr.open_dataset(out_xyz) as ds:
        np.testing.assert_array_equal(ds["depth"].values, ds["mean"].values)
