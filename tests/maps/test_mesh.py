"""Tests of the Open3D bridge (tangraph.maps.mesh): meshes, TIN gridding, ray casting, and mesh
files (round trips, z-up vertices, sidecars with the CRS and the origin)."""

from __future__ import annotations

import json
import re

import numpy as np
import pyproj
import pytest

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.mesh import (
    cast_rays,
    from_mesh,
    raycasting_scene,
    read_mesh,
    to_mesh,
    triangles_to_map,
    write_mesh,
)
from tests.maps.mesh_cases import CRS, ORIGIN, _ply_vertices, small_map


def flat_map(ny: int, nx: int, depth: float = 50.0, cell: float = 1.0, n0: float = 0.0):
    return BathymetryMap(
        north=n0 + cell * np.arange(ny), east=cell * np.arange(nx), depth=np.full((ny, nx), depth)
    )


def with_nan(m: BathymetryMap, *cells: tuple[int, int]) -> BathymetryMap:
    depth = np.array(m.depth)
    for ij in cells:
        depth[ij] = np.nan
    return m.replace(depth=depth)


# Smooth test surface: depth = D0 + A sin(kn n) cos(ke e), so |d2 depth / dn de| <= A kn ke.
D0, A, KN, KE = 60.0, 4.0, 2 * np.pi / 37.0, 2 * np.pi / 23.0


def smooth_map(cell: float = 1.5) -> BathymetryMap:
    north = 200.0 + cell * np.arange(40)
    east = -30.0 + cell * np.arange(50)
    nn, ee = np.meshgrid(north, east, indexing="ij")
    return BathymetryMap(north, east, D0 + A * np.sin(KN * nn) * np.cos(KE * ee), name="sines")


# -- to_mesh -----------------------------------------------------------------------------------
def test_to_mesh_full_grid_counts_vertices_and_normals():
    m = flat_map(4, 5, depth=30.0)
    mesh = to_mesh(m)
    assert len(mesh.vertices) == 20
    assert len(mesh.triangles) == 2 * 3 * 4
    v = np.asarray(mesh.vertices)
    nn, ee = np.meshgrid(m.north, m.east, indexing="ij")
    np.testing.assert_array_equal(v, np.column_stack([nn.ravel(), ee.ravel(), m.depth.ravel()]))
    normals = np.asarray(mesh.vertex_normals)
    np.testing.assert_allclose(normals, np.tile([0.0, 0.0, -1.0], (20, 1)), atol=1e-12)


@pytest.mark.parametrize(
    ("cell", "squares_lost"),
    [((2, 2), 4), ((0, 0), 1), ((0, 2), 2), ((4, 5), 1), ((2, 5), 2)],
)
def test_to_mesh_nan_cell_leaves_out_the_squares_around_it(cell, squares_lost):
    m = with_nan(flat_map(5, 6), cell)
    mesh = to_mesh(m)
    assert len(mesh.triangles) == 2 * (4 * 5 - squares_lost)
    assert len(mesh.vertices) == 5 * 6 - 1
    v = np.asarray(mesh.vertices)
    assert not np.any((v[:, 0] == m.north[cell[0]]) & (v[:, 1] == m.east[cell[1]]))


def test_to_mesh_removes_vertices_no_triangle_uses():
    # 3 x 4 grid, NaN at (1, 1): only the squares of columns 2..3 survive.
    mesh = to_mesh(with_nan(flat_map(3, 4), (1, 1)))
    assert len(mesh.triangles) == 4
    v = np.asarray(mesh.vertices)
    assert len(v) == 6
    assert set(v[:, 1]) == {2.0, 3.0}
    assert np.asarray(mesh.triangles).max() == 5


# -- ray casting -------------------------------------------------------------------------------
def test_round_trip_vertical_rays_match_depth_at_within_the_interpolation_bound():
    """Mesh depth (piecewise linear) vs bilinear depth_at on the same cells.

    On a square with normalised coordinates x, y in [0, 1] and corner values f00, f10, f01,
    f11, bilinear minus the triangle interpolant is -c y (1 - x) on one triangle (and
    -c x (1 - y) on the other), with the twist c = f00 - f10 - f01 + f11 = dn de f_ne(xi)
    for some xi in the square. So |difference| <= dn de max|f_ne| / 4 = dn de A kn ke / 4.
    """
    m = smooth_map(cell=1.5)
    dn, de = m.cell_size
    bound = dn * de * A * KN * KE / 4
    scene = raycasting_scene(m)
    rng = np.random.default_rng(7)
    n = rng.uniform(m.north[0], m.north[-1], 20_000)
    e = rng.uniform(m.east[0], m.east[-1], 20_000)
    ranges = cast_rays(scene, np.column_stack([n, e, np.full(n.size, -5.0)]), [0.0, 0.0, 1.0])
    assert np.all(np.isfinite(ranges))
    diff = np.abs(ranges - 5.0 - m.depth_at(n, e))
    assert diff.max() <= bound * (1 + 1e-9)
    assert diff.max() > 0.25 * bound  # the mesh is triangles, not the bilinear surface
    # At cell centres (the outer north/east edges excepted: Embree's edges are half-open)
    # mesh and grid agree.
    nn, ee = np.meshgrid(m.north[:-1], m.east[:-1], indexing="ij")
    o = np.stack([nn, ee, np.full(nn.shape, -5.0)], axis=-1)
    np.testing.assert_allclose(cast_rays(scene, o, [0, 0, 2.0]) - 5.0, m.depth[:-1, :-1], atol=1e-6)


@pytest.mark.parametrize("n0", [0.0, 3.0e4])
def test_slanted_rays_on_a_flat_seabed(n0):
    depth, z = 80.0, 30.0
    m = flat_map(3, 3, depth=depth, cell=500.0, n0=n0)
    scene = raycasting_scene(m)
    theta = np.deg2rad(np.array([0.0, 10, 25, 45, 60, 70]))
    phi = np.deg2rad(np.array([0.0, 30, 100, 200, 290, 345]))
    d = np.column_stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)])
    origin = [n0 + 500.0, 500.0, z]
    expected = (depth - z) / np.cos(theta)
    np.testing.assert_allclose(cast_rays(scene, origin, d), expected, rtol=1e-12)
    np.testing.assert_allclose(cast_rays(scene, origin, 3.5 * d), expected, rtol=1e-12)
    up = cast_rays(scene, np.tile(origin, (2, 1)), [[0, 0, -1.0], [1.0, 0, -0.1]])
    assert np.all(np.isinf(up))


def test_cast_rays_keeps_leading_shape():
    scene = raycasting_scene(flat_map(3, 3, cell=10.0))
    o = np.full((2, 4, 3), [10.0, 10.0, 0.0])
    assert cast_rays(scene, o, [0, 0, 1]).shape == (2, 4)


# -- TIN -> map --------------------------------------------------------------------------------
def plane(n, e):
    return 20.0 + 0.3 * n - 0.2 * e


def test_triangles_to_map_reproduces_a_plane_and_is_nan_off_the_tin():
    # An L-shaped TIN (reflex corner at (4, 4)) shifted away from the origin.
    n0, e0 = 1000.25, -2000.5
    corners = np.array([[0, 0], [4, 0], [10, 0], [10, 4], [4, 4], [0, 4], [4, 10], [0, 10]], float)
    corners += [n0, e0]
    vertices = np.column_stack([corners, plane(corners[:, 0], corners[:, 1])])
    triangles = [[0, 1, 4], [0, 4, 5], [1, 2, 3], [1, 3, 4], [5, 4, 6], [5, 6, 7]]
    m = triangles_to_map(vertices, triangles, cell=0.5, name="L")
    assert m.shape == (21, 21)
    np.testing.assert_allclose(m.north, n0 + 0.5 * np.arange(21), atol=1e-9)
    nn, ee = np.meshgrid(m.north - n0, m.east - e0, indexing="ij")
    tol = 1e-9
    inside = ((nn >= -tol) & (nn <= 10 + tol) & (ee >= -tol) & (ee <= 4 + tol)) | (
        (nn >= -tol) & (nn <= 4 + tol) & (ee >= -tol) & (ee <= 10 + tol)
    )
    np.testing.assert_array_equal(np.isfinite(m.depth), inside)
    nn, ee = np.meshgrid(m.north, m.east, indexing="ij")
    np.testing.assert_allclose(m.depth[inside], plane(nn, ee)[inside], rtol=0, atol=1e-6)


def test_map_mesh_map_round_trip_is_exact_with_holes():
    m = with_nan(smooth_map(cell=2.0), (5, 7), (0, 0), (39, 20))
    back = from_mesh(to_mesh(m), cell=2.0, name=m.name)
    np.testing.assert_allclose(back.north, m.north, atol=1e-9)
    np.testing.assert_allclose(back.east, m.east, atol=1e-9)
    # The squares next to a NaN are gone from the mesh, so their inner points are NaN too,
    # but every cell centre, edges and hole rims included, comes back.
    np.testing.assert_array_equal(np.isfinite(back.depth), np.isfinite(m.depth))
    np.testing.assert_allclose(back.depth, m.depth, atol=1e-9, equal_nan=True)


# -- files -------------------------------------------------------------------------------------
@pytest.mark.parametrize(("suffix", "atol"), [(".ply", 1e-12), (".obj", 1e-4)])
def test_mesh_file_round_trip(tmp_path, suffix, atol):
    m = with_nan(smooth_map(cell=2.0).crop(north=(200, 240), east=(-30, 10)), (4, 6))
    path = write_mesh(m, tmp_path / f"survey{suffix}")
    assert path.is_file()
    back = read_mesh(path, cell=2.0, crs="EPSG:32632", origin=(5.0e6, 4.0e5))
    assert back.name == "survey"
    assert back.crs == "EPSG:32632"
    assert back.origin == (5.0e6, 4.0e5)
    np.testing.assert_allclose(back.north, m.north, atol=atol)
    np.testing.assert_allclose(back.east, m.east, atol=atol)
    np.testing.assert_array_equal(np.isfinite(back.depth), np.isfinite(m.depth))
    np.testing.assert_allclose(back.depth, m.depth, atol=atol, equal_nan=True)


@pytest.mark.parametrize("suffix", [".ply", ".obj"])
def test_mesh_z_up_vertices_are_east_north_elevation(tmp_path, suffix):
    m = small_map()
    ned = write_mesh(m, tmp_path / f"ned{suffix}")
    enu = write_mesh(m, tmp_path / f"enu{suffix}", z_up=True)
    assert not (tmp_path / f"ned{suffix}.json").exists()  # a sidecar only when asked
    (vn, tn), (ve, te) = _ply_vertices(ned), _ply_vertices(enu)
    np.testing.assert_allclose(ve, np.column_stack([vn[:, 1], vn[:, 0], -vn[:, 2]]), atol=1e-5)
    np.testing.assert_array_equal(te, tn)
    assert np.all(ve[:, 2] < 0) and np.isclose(ve[:, 2].max(), -20.0, atol=1e-5)
    # triangles face up (+z) in the z-up mesh: cross product of the edges
    a, b, c = ve[te[:, 0]], ve[te[:, 1]], ve[te[:, 2]]
    assert np.all(np.cross(b - a, c - a)[:, 2] > 0)


@pytest.mark.parametrize("z_up", [False, True])
def test_mesh_sidecar_holds_crs_origin_units_and_axes(tmp_path, z_up):
    m = small_map()
    path = write_mesh(m, tmp_path / "lake.ply", z_up=z_up, sidecar=True)
    about = json.loads((tmp_path / "lake.ply.json").read_text())
    assert about["crs"] == CRS
    assert pyproj.CRS.from_wkt(about["crs_wkt"]).to_epsg() == 32755
    assert about["origin"] == {"northing": ORIGIN[0], "easting": ORIGIN[1]}
    assert about["units"] == "m" and about["map"] == "lake"
    assert about["axes"] == (["east", "north", "up"] if z_up else ["north", "east", "down"])
    assert about["up"] == ("+z" if z_up else "-z")
    assert path.is_file()
    local = json.loads(write_mesh(small_map(None), tmp_path / "local.obj", sidecar=True)
                       .with_name("local.obj.json").read_text())
    assert local["crs"] is None and local["crs_wkt"] is None


# -- bad input ---------------------------------------------------------------------------------
def test_read_mesh_errors_name_the_file(tmp_path):
    missing = tmp_path / "nothing.ply"
    with pytest.raises(MapFormatError, match=re.escape(str(missing))):
        read_mesh(missing, cell=1.0)
    with pytest.raises(MapFormatError, match=r"nothing\.stl.*\.ply or \.obj"):
        read_mesh(tmp_path / "nothing.stl", cell=1.0)
    garbage = tmp_path / "garbage.ply"
    garbage.write_text("not a mesh")
    with pytest.raises(MapFormatError, match=re.escape(str(garbage))):
        read_mesh(garbage, cell=1.0)
    tiny = write_mesh(flat_map(3, 3), tmp_path / "tiny.ply")
    with pytest.raises(TangraphError, match=re.escape(str(tiny)) + ".*smaller cell"):
        read_mesh(tiny, cell=5.0)


@pytest.mark.parametrize("name", ["a.ply", "a.obj"])
def test_write_mesh_errors_name_the_file(tmp_path, name):
    target = tmp_path / "no_such_dir" / name
    with pytest.raises(TangraphError, match=re.escape(str(target))):
        write_mesh(flat_map(3, 3), target)
    with pytest.raises(MapFormatError, match=r"\.xyz"):
        write_mesh(flat_map(3, 3), tmp_path / "a.xyz")


def test_to_mesh_needs_a_block_of_data():
    m = with_nan(flat_map(3, 3), (1, 1))
    with pytest.raises(TangraphError, match="no 2 x 2 block"):
        to_mesh(m)


VERTS = [[0.0, 0, 1], [1, 0, 1], [0, 1, 1]]


@pytest.mark.parametrize(
    ("vertices", "triangles", "cell", "error", "pattern"),
    [
        ([[0.0, 0], [1, 0], [0, 1]], [[0, 1, 2]], 0.1, MapFormatError, "vertices.*shape"),
        ([[0.0, 0, np.nan], [1, 0, 1], [0, 1, 1]], [[0, 1, 2]], 0.1, MapFormatError, "vertices"),
        (VERTS, [[0, 1, 3]], 0.1, MapFormatError, "triangles index .* 3 vertices"),
        (VERTS, [[0, -1, 2]], 0.1, MapFormatError, "triangles index"),
        (VERTS, [[0.0, 1.0, 2.0]], 0.1, MapFormatError, "triangles must hold integer"),
        (VERTS, [0, 1, 2], 0.1, MapFormatError, "triangles must have shape"),
        (VERTS, [[0, 1, 2]], 0.0, TangraphError, "cell must be"),
        (VERTS, [[0, 1, 2]], np.nan, TangraphError, "cell must be"),
        (VERTS, [[0, 1, 2]], 2.0, TangraphError, "north spans"),
    ],
)
def test_triangles_to_map_rejects_bad_input(vertices, triangles, cell, error, pattern):
    with pytest.raises(error, match=pattern):
        triangles_to_map(vertices, triangles, cell=cell)


def test_cast_rays_rejects_bad_rays():
    scene = raycasting_scene(flat_map(3, 3))
    with pytest.raises(TangraphError, match="origins and directions must have shape"):
        cast_rays(scene, [[0.0, 0.0]], [0.0, 0.0, 1.0])
    with pytest.raises(TangraphError, match="zero vector"):
        cast_rays(scene, [1.0, 1.0, 0.0], [[0.0, 0.0, 0.0]])
    with pytest.raises(TangraphError, match="origins hold non-finite"):
        cast_rays(scene, [np.nan, 1.0, 0.0], [0.0, 0.0, 1.0])
    with pytest.raises(TangraphError, match="do not broadcast"):
        cast_rays(scene, np.zeros((2, 3)), np.ones((3, 3)))


def test_linear_tin_gridding_agrees_with_ray_casting_and_falls_back_for_overlaps():
    from pathlib import Path

    from tangraph.maps.io import read_tsh

    verts, tris, _ = read_tsh(Path(__file__).resolve().parents[2] / "maps" / "merimbula_10785_1.tsh")
    v = np.column_stack([verts[:, 1] - verts[:, 1].min(), verts[:, 0] - verts[:, 0].min(), -verts[:, 2]])
    linear = triangles_to_map(v, tris, cell=25.0, method="linear")
    ray = triangles_to_map(v, tris, cell=25.0, method="raycast")
    np.testing.assert_array_equal(np.isfinite(linear.depth), np.isfinite(ray.depth))
    np.testing.assert_allclose(linear.depth, ray.depth, atol=2e-6, equal_nan=True)
    # two overlapping triangles (a fold): matplotlib refuses them, ray casting takes the shallowest
    folded = [[0.0, 0, 10], [4, 0, 10], [0, 4, 10], [0.0, 0, 5], [4, 0, 5], [0, 4, 5]]
    m = triangles_to_map(folded, [[0, 1, 2], [3, 4, 5]], cell=2.0)
    assert m.depth[0, 0] == pytest.approx(5.0)
