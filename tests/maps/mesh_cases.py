"""A small sloping lake map in EPSG:32755, and a mesh file's vertices and triangles read back with
Open3D: shared by the mesh tests and the ``maps mesh`` command's."""

from __future__ import annotations

import numpy as np

from tangraph.maps import BathymetryMap

CRS, ORIGIN = "EPSG:32755", (5.9e6, 7.5e5)


def small_map(crs: str | None = CRS) -> BathymetryMap:
    north, east = np.arange(4.0) * 2, np.arange(5.0) * 3
    depth = 20.0 + north[:, None] + 0.1 * east[None, :]
    return BathymetryMap(north, east, depth, crs=crs, origin=ORIGIN, name="lake")


def _ply_vertices(path) -> np.ndarray:
    import open3d as o3d

    mesh = o3d.io.read_triangle_mesh(str(path))
    return np.asarray(mesh.vertices), np.asarray(mesh.triangles)
