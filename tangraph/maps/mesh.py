"""The Open3D bridge: maps as triangle meshes, meshes (TINs) as maps, ray casting.

Mesh and point-cloud coordinates are ``(north, east, depth)``: the right-handed NED frame
(x north, y east, z down), in metres, in the map's local frame.

Open3D ray casting is float32. Two things keep results at float64 accuracy: the scene is
built around its own centre (so large local coordinates lose little), and every hit is
refined in float64 on the triangle Open3D reports (a plane intersection for :func:`cast_rays`,
barycentric interpolation for :func:`triangles_to_map`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Literal

import numpy as np
import open3d as o3d

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps._grid_checks import cell_axis, check_cell
from tangraph.maps.grid import BathymetryMap
from tangraph.outputs import write_atomically

__all__ = [
    "TerrainScene",
    "cast_rays",
    "from_mesh",
    "raycasting_scene",
    "read_mesh",
    "to_mesh",
    "triangles_to_map",
    "write_mesh",
]


_CHUNK = 1 << 21  # rays per cast_rays call (2M rays: 48 MB of float32)
_MESH_SUFFIXES = (".ply", ".obj")
_INVALID = o3d.t.geometry.RaycastingScene.INVALID_ID
# Nudges tried for vertical rays that slip past a TIN's boundary (Embree's half-open edges).
_NUDGES = np.array([[1, 1], [1, -1], [-1, 1], [-1, -1], [1, 0], [-1, 0], [0, 1], [0, -1]], float)


# -- map -> mesh ------------------------------------------------------------------------------
def _mesh_arrays(bathymetry: BathymetryMap) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (N, 3) and triangles (M, 3) of the map's surface, unused vertices removed."""
    ny, nx = bathymetry.shape
    valid = np.isfinite(bathymetry.depth)
    square = valid[:-1, :-1] & valid[1:, :-1] & valid[1:, 1:] & valid[:-1, 1:]
    if not square.any():
        raise TangraphError(f"map {bathymetry.name!r} has no 2 x 2 block of data cells to mesh")
    idx = np.arange(ny * nx).reshape(ny, nx)
    a, b = idx[:-1, :-1][square], idx[1:, :-1][square]
    c, d = idx[1:, 1:][square], idx[:-1, 1:][square]
    # Wound so that normals point up into the water (negative z in NED).
    triangles = np.concatenate([np.stack([a, c, b], 1), np.stack([a, d, c], 1)])
    used = np.zeros(ny * nx, bool)
    used[triangles] = True
    renumber = np.cumsum(used) - 1
    nn, ee = np.meshgrid(bathymetry.north, bathymetry.east, indexing="ij")
    vertices = np.column_stack([nn.ravel(), ee.ravel(), bathymetry.depth.ravel()])[used]
    return vertices, renumber[triangles]


def to_mesh(bathymetry: BathymetryMap) -> o3d.geometry.TriangleMesh:
    """The map as a triangle mesh: a vertex per cell centre, two triangles per grid square.

    Squares with a NaN corner are left out (where :meth:`BathymetryMap.depth_at` is NaN), and
    so are the vertices no triangle uses. Each square is split along its (i, j)-(i+1, j+1)
    diagonal; vertex normals are computed and point up (negative depth component).

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> m = BathymetryMap(north=[0.0, 1, 2], east=[0.0, 1, 2], depth=np.full((3, 3), 50.0))
    >>> mesh = to_mesh(m)
    >>> len(mesh.vertices), len(mesh.triangles)
    (9, 8)
    """
    vertices, triangles = _mesh_arrays(bathymetry)
    mesh = o3d.geometry.TriangleMesh(
        o3d.utility.Vector3dVector(vertices),
        o3d.utility.Vector3iVector(triangles.astype(np.int32)),
    )
    mesh.compute_vertex_normals()
    return mesh


# -- ray casting ------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True, eq=False)
class TerrainScene:
    """An Open3D ray-casting scene of a seabed with its float64 geometry.

    ``scene`` is the ``open3d.t.geometry.RaycastingScene`` holding ``vertices - offset`` in
    float32; ``vertices (N, 3)`` and ``triangles (M, 3)`` are the float64 originals used to
    refine hits. Build it with :func:`raycasting_scene`.
    """

    scene: o3d.t.geometry.RaycastingScene
    vertices: np.ndarray
    triangles: np.ndarray
    offset: np.ndarray

    @classmethod
    def from_triangles(cls, vertices: np.ndarray, triangles: np.ndarray) -> TerrainScene:
        """A scene of checked ``vertices (N, 3)`` and ``triangles (M, 3)``."""
        vertices = np.array(vertices, dtype=np.float64)
        triangles = np.array(triangles, dtype=np.int64)
        offset = 0.5 * (vertices.min(axis=0) + vertices.max(axis=0))
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(
            o3d.core.Tensor((vertices - offset).astype(np.float32)),  # type: ignore[call-overload]
            o3d.core.Tensor(triangles.astype(np.uint32)),  # type: ignore[call-overload]
        )
        for a in (vertices, triangles, offset):
            a.setflags(write=False)
        return cls(scene, vertices, triangles, offset)

    def first_hits(self, origins: np.ndarray, directions: np.ndarray):
        """Float32 ranges and hit triangle (-1 for none) of rays ``(N, 3)``, cast in chunks."""
        rays = np.empty((origins.shape[0], 6), np.float32)
        rays[:, :3] = origins - self.offset
        rays[:, 3:] = directions
        t = np.empty(rays.shape[0])
        prim = np.empty(rays.shape[0], np.int64)
        for start in range(0, rays.shape[0], _CHUNK):
            hit = self.scene.cast_rays(o3d.core.Tensor(rays[start : start + _CHUNK]))  # type: ignore[call-overload]
            t[start : start + _CHUNK] = hit["t_hit"].numpy()
            ids = hit["primitive_ids"].numpy().astype(np.int64)
            prim[start : start + _CHUNK] = np.where(ids == _INVALID, -1, ids)
        return t, prim


def raycasting_scene(bathymetry: BathymetryMap) -> TerrainScene:
    """A ray-casting scene of the map's mesh (:func:`to_mesh`), for :func:`cast_rays`."""
    return TerrainScene.from_triangles(*_mesh_arrays(bathymetry))


def _as_rays(origins, directions) -> tuple[np.ndarray, np.ndarray, tuple[int, ...]]:
    o = np.asarray(origins, dtype=np.float64)
    d = np.asarray(directions, dtype=np.float64)
    if o.shape[-1:] != (3,) or d.shape[-1:] != (3,):
        raise TangraphError(
            f"origins and directions must have shape (..., 3), got {o.shape} and {d.shape}"
        )
    try:
        o, d = np.broadcast_arrays(o, d)
    except ValueError:
        raise TangraphError(
            f"origins {o.shape} and directions {d.shape} do not broadcast"
        ) from None
    shape = o.shape[:-1]
    o, d = o.reshape(-1, 3), d.reshape(-1, 3)
    for name, a in (("origins", o), ("directions", d)):
        if not np.all(np.isfinite(a)):
            raise TangraphError(f"{name} hold non-finite values")
    norm = np.linalg.norm(d, axis=1)
    if np.any(norm == 0):
        raise TangraphError(f"directions hold {int(np.sum(norm == 0))} zero vector(s)")
    return o, d / norm[:, None], shape


def cast_rays(scene: TerrainScene, origins, directions) -> np.ndarray:
    """Range (metres) along each ray to the first hit on the seabed; ``inf`` where none.

    Parameters
    ----------
    scene : TerrainScene
        From :func:`raycasting_scene`.
    origins, directions : array_like, shapes broadcasting to (..., 3)
        Ray origins and directions ``(north, east, down)``; directions are normalised, so the
        range is in metres whatever their length.

    Returns
    -------
    ndarray, shape (...)
        The range, found by Open3D and refined in float64 on the triangle hit.

    Notes
    -----
    Embree treats triangle edges as half-open, so a ray through exactly the outer edge of the
    mesh (e.g. a vertical ray at a cell centre of the last row or column) may miss.

    Examples
    --------
    >>> import numpy as np
    >>> from tangraph.maps import BathymetryMap
    >>> m = BathymetryMap(north=[0.0, 100], east=[0.0, 100], depth=np.full((2, 2), 40.0))
    >>> s = raycasting_scene(m)
    >>> cast_rays(s, [5.0, 5.0, 10.0], [[0, 0, 1], [0, 1, 1], [0, 0, -1]]).round(6)
    array([30.      , 42.426407,       inf])
    """
    o, d, shape = _as_rays(origins, directions)
    t, prim = scene.first_hits(o, d)
    hit = prim >= 0
    a, b, c = (scene.vertices[scene.triangles[prim[hit], k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    den = np.einsum("ij,ij->i", normal, d[hit])
    num = np.einsum("ij,ij->i", normal, a - o[hit])
    ok = np.abs(den) > 1e-12 * np.linalg.norm(normal, axis=1)
    t[hit] = np.where(ok, num / np.where(ok, den, 1.0), t[hit])
    return t.reshape(shape)


# -- mesh (TIN) -> map ------------------------------------------------------------------------
def _check_tin(vertices, triangles) -> tuple[np.ndarray, np.ndarray]:
    v = np.asarray(vertices)
    t = np.asarray(triangles)
    if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] < 3:
        raise MapFormatError(f"vertices must have shape (N >= 3, 3), got {v.shape}")
    if not np.issubdtype(v.dtype, np.number) or not np.all(np.isfinite(v)):
        raise MapFormatError("vertices hold non-finite or non-numeric values")
    if t.ndim != 2 or t.shape[1] != 3 or t.shape[0] < 1:
        raise MapFormatError(f"triangles must have shape (M >= 1, 3), got {t.shape}")
    if not np.issubdtype(t.dtype, np.integer):
        raise MapFormatError(f"triangles must hold integer vertex indices, got dtype {t.dtype}")
    if t.min() < 0 or t.max() >= v.shape[0]:
        raise MapFormatError(
            f"triangles index vertices {t.min()}..{t.max()}, but there are {v.shape[0]} vertices"
        )
    return v.astype(np.float64), t.astype(np.int64)


def _depth_on(scene: TerrainScene, prim, north, east):
    """Linear depth on triangles ``prim`` at (north, east) and the smallest barycentric weight."""
    a, b, c = (scene.vertices[scene.triangles[prim, k]] for k in range(3))
    u, v = b[:, :2] - a[:, :2], c[:, :2] - a[:, :2]
    pn, pe = north - a[:, 0], east - a[:, 1]
    den = u[:, 0] * v[:, 1] - v[:, 0] * u[:, 1]
    ok = den != 0  # a vertical triangle has no depth of its own at a point
    den = np.where(ok, den, 1.0)
    w1 = (pn * v[:, 1] - v[:, 0] * pe) / den
    w2 = (u[:, 0] * pe - pn * u[:, 1]) / den
    w0 = 1.0 - w1 - w2
    depth = w0 * a[:, 2] + w1 * b[:, 2] + w2 * c[:, 2]
    return np.where(ok, depth, np.nan), np.where(ok, np.minimum(w0, np.minimum(w1, w2)), -np.inf)


def _vertical_depths(scene: TerrainScene, north: np.ndarray, east: np.ndarray) -> np.ndarray:
    """Depth of the first surface under each point, by vertical rays; NaN where there is none."""
    top = scene.vertices[:, 2].min() - 1.0
    origins = np.column_stack([north, east, np.full(north.size, top)])
    down = np.broadcast_to([0.0, 0.0, 1.0], origins.shape)
    t, prim = scene.first_hits(origins, down)
    depth = np.full(north.size, np.nan)
    hit = prim >= 0
    depth[hit], _ = _depth_on(scene, prim[hit], north[hit], east[hit])
    depth[hit] = np.where(np.isnan(depth[hit]), top + t[hit], depth[hit])
    # Embree's edges are half-open: points exactly on the TIN's outer edge slip through.
    # Retry those with tiny nudges and keep a hit only if the exact point lies on its triangle.
    scale = max(1.0, float(np.max(np.abs(scene.vertices - scene.offset))))
    eps = 64 * float(np.finfo(np.float32).eps) * scale
    for nudge in _NUDGES:
        miss = np.flatnonzero(~hit)
        if miss.size == 0:
            break
        moved = origins[miss].copy()
        moved[:, :2] += eps * nudge
        _, p = scene.first_hits(moved, down[: miss.size])
        got = miss[p >= 0]
        z, w_min = _depth_on(scene, p[p >= 0], north[got], east[got])
        keep = w_min >= -1e-9
        depth[got[keep]] = z[keep]
        hit[got[keep]] = True
    return depth


def triangles_to_map(
    vertices,
    triangles,
    *,
    cell: float,
    name: str = "mesh",
    crs: str | None = None,
    origin: tuple[float, float] = (0.0, 0.0),
    method: Literal["linear", "raycast"] = "linear",
) -> BathymetryMap:
    """Grid a triangulated surface (a TIN) onto a regular grid.

    Parameters
    ----------
    vertices : array_like, shape (N, 3)
        ``(north, east, depth)`` of the TIN's vertices, metres, depth positive down.
    triangles : array_like of int, shape (M, 3)
        Vertex indices of each triangle.
    cell : float
        Cell size in metres. Cell centres start at the vertices' smallest north and east and
        step by ``cell`` while inside their extent.
    name, crs, origin
        As in :class:`BathymetryMap`.
    method : {"linear", "raycast"}
        ``"linear"``: linear interpolation in the triangle under each centre
        (``matplotlib.tri.LinearTriInterpolator``), for a TIN that is a surface over the plane
        (no overlapping triangles, no repeated vertices); a TIN that is not falls back to ray
        casting. ``"raycast"``: vertical rays cast by Open3D onto the shallowest surface, for
        any mesh. On the shipped Merimbula TIN the two agree to 1.2e-6 m (at 2 m cells, 8 of
        5.3 million centres on the TIN's outer edge differ in whether they hold data) and linear
        is 2-8x faster, the more the finer the cells (``benchmarks/bench_tin.py``).

    Examples
    --------
    >>> v = [[0.0, 0, 10], [4, 0, 14], [0, 4, 10]]
    >>> m = triangles_to_map(v, [[0, 1, 2]], cell=2.0)
    >>> m.depth
    array([[10., 10., 10.],
           [12., 12., nan],
           [14., nan, nan]])
    """
    where = f"TIN {name!r}"
    cell = check_cell(cell, where)
    v, t = _check_tin(vertices, triangles)
    north = cell_axis(v[:, 0].min(), v[:, 0].max(), cell, "north", where)
    east = cell_axis(v[:, 1].min(), v[:, 1].max(), cell, "east", where)
    nn, ee = np.meshgrid(north, east, indexing="ij")
    depth = _linear_depths(v, t, nn.ravel(), ee.ravel()) if method == "linear" else None
    if method not in ("linear", "raycast"):
        raise TangraphError(f"{where}: method must be 'linear' or 'raycast', got {method!r}")
    if depth is None:
        depth = _vertical_depths(TerrainScene.from_triangles(v, t), nn.ravel(), ee.ravel())
    if not np.any(np.isfinite(depth)):
        raise MapFormatError(f"{where}: no cell centre lies on a triangle; use a smaller cell")
    return BathymetryMap(north, east, depth.reshape(nn.shape), crs=crs, origin=origin, name=name)


def _linear_depths(v: np.ndarray, t: np.ndarray, north: np.ndarray, east: np.ndarray) -> np.ndarray | None:
    """Linear interpolation of the TIN's depth at points (NaN off it); None when matplotlib
    refuses the triangulation (overlapping triangles, repeated vertices)."""
    import matplotlib.tri as mtri

    try:
        tin = mtri.Triangulation(v[:, 1], v[:, 0], t)
        values = mtri.LinearTriInterpolator(tin, v[:, 2])(east, north)
    except (RuntimeError, ValueError):
        return None
    return np.ma.filled(values.astype(np.float64), np.nan)


def from_mesh(mesh: o3d.geometry.TriangleMesh, *, cell: float, name: str = "mesh", **kwargs):
    """:func:`triangles_to_map` of an Open3D mesh with ``(north, east, depth)`` vertices."""
    return triangles_to_map(
        np.asarray(mesh.vertices), np.asarray(mesh.triangles), cell=cell, name=name, **kwargs
    )


# -- files ------------------------------------------------------------------------------------
def _mesh_path(path, *, must_exist: bool) -> Path:
    path = Path(path)
    if path.suffix.lower() not in _MESH_SUFFIXES:
        raise MapFormatError(
            f"mesh file {str(path)!r}: unsupported suffix {path.suffix!r}; use .ply or .obj"
        )
    if must_exist and not path.is_file():
        raise MapFormatError(f"mesh file {str(path)!r} does not exist")
    return path


def read_mesh(path, *, cell: float, name: str | None = None, **kwargs) -> BathymetryMap:
    """Read a PLY or OBJ triangle mesh (``north, east, depth`` vertices) and grid it.

    ``cell``, ``crs`` and ``origin`` are passed to :func:`triangles_to_map`; ``name`` defaults
    to the file's stem. Open3D reads OBJ coordinates in float32; PLY keeps float64.
    """
    path = _mesh_path(path, must_exist=True)
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        mesh = o3d.io.read_triangle_mesh(str(path))  # type: ignore[arg-type]
    if len(mesh.triangles) == 0:
        raise MapFormatError(f"mesh file {str(path)!r} is unreadable or holds no triangles")
    try:
        return from_mesh(mesh, cell=cell, name=name or path.stem, **kwargs)
    except TangraphError as err:
        raise type(err)(f"mesh file {str(path)!r}: {err}") from None


def write_mesh(
    bathymetry: BathymetryMap, path, *, z_up: bool = False, sidecar: bool | str | Path = False
) -> Path:
    """Write the map's mesh (:func:`to_mesh`) as PLY (binary, float64) or OBJ (text).

    The vertices are local ``(north, east, depth)`` (NED: x north, y east, z down), or with
    ``z_up`` ``(east, north, elevation = -depth)``: a right-handed ENU mesh (x east, y north, z up)
    for viewers that expect z up; triangles face up (into the water) either way. OBJ is written
    here at full precision (Open3D's writer keeps 6 digits).

    The mesh file holds no CRS. ``sidecar=True`` writes it next to the mesh as JSON, named
    after it (``lake.ply`` -> ``lake.ply.json``; a path: there): ``crs`` (as given) and
    ``crs_wkt``, ``origin`` (northing, easting in the CRS of local north = east = 0),
    ``units``, ``axes`` (what x, y, z are), ``up`` and ``frame``; a projected point is
    ``easting = origin.easting + east``, ``northing = origin.northing + north``.
    """
    path = _mesh_path(path, must_exist=False)
    axes = ["east", "north", "up"] if z_up else ["north", "east", "down"]
    if path.suffix.lower() == ".obj":
        vertices, triangles = _mesh_arrays(bathymetry)
        if z_up:
            vertices = np.column_stack([vertices[:, 1], vertices[:, 0], -vertices[:, 2]])
        what = "east north elevation (m, ENU, z up)" if z_up else "north east depth (m, NED)"
        try:
            with path.open("w") as f:
                f.write(f"# {bathymetry.name}: {what}\n")
                np.savetxt(f, vertices, fmt="v %.17g %.17g %.17g")
                np.savetxt(f, triangles + 1, fmt="f %d %d %d")
        except OSError as err:
            raise TangraphError(f"cannot write mesh file {str(path)!r}: {err}") from None
    else:
        mesh = to_mesh(bathymetry)
        if z_up:  # a proper rotation (det +1): the winding, and so the up-facing normals, stay
            v = np.asarray(mesh.vertices)
            mesh.vertices = o3d.utility.Vector3dVector(np.column_stack([v[:, 1], v[:, 0], -v[:, 2]]))
            mesh.compute_vertex_normals()
        with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
            ok = o3d.io.write_triangle_mesh(str(path), mesh)  # type: ignore[arg-type]
        if not ok:
            raise TangraphError(f"cannot write mesh file {str(path)!r}")
    if sidecar is not False:
        import json

        target = path.with_name(path.name + ".json") if sidecar is True else Path(sidecar)
        crs_wkt = None
        if bathymetry.crs is not None:
            import pyproj

            crs_wkt = pyproj.CRS.from_user_input(bathymetry.crs).to_wkt()
        about = {
            "map": bathymetry.name,
            "crs": bathymetry.crs,
            "crs_wkt": crs_wkt,
            "origin": {"northing": bathymetry.origin[0], "easting": bathymetry.origin[1]},
            "units": "m",
            "axes": axes,
            "up": "+z" if z_up else "-z",
            "frame": "ENU" if z_up else "NED",
            "z": "elevation (-depth, positive up)" if z_up else "depth (positive down)",
        }
        text = json.dumps(about, indent=2) + "\n"
        write_atomically(target, True, lambda tmp: tmp.write_text(text, encoding="utf-8"))
    return path
