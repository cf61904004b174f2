"""
Maps: load, plot, mesh and grid soundings
=========================================

Every estimator in tangraph asks one question many times: *how deep is the seafloor here?*
This tutorial walks through the maps layer that answers it: the catalogue of shipped maps,
:class:`~tangraph.maps.BathymetryMap` and its interpolation, cropping and resampling, terrain
statistics, the Open3D bridge (meshes and ray casting) and the gridding of scattered
soundings.

Coordinates are local north-east-down in metres, ``(north, east)`` in that order, and depth is
positive down (see :doc:`/conventions`).
"""

# %%
# The catalogue
# -------------
#
# A few real grids and two seeded synthetic charts ship with tangraph. Each has a name, a
# title, a licence and its source.

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt
import numpy as np

from tangraph.maps import (
    cast_rays,
    catalogue,
    grid_soundings,
    load,
    raycasting_scene,
    read_map,
    to_mesh,
    write_map,
)
from tangraph.maps.statistics import roughness, slope
from tangraph.plot import plot_map

for entry in catalogue().values():
    print(f"{entry.name:<14} {entry.title}")

# %%
# Load two maps
# -------------
#
# :func:`~tangraph.maps.load` reads a catalogue map by name (once per process: maps are
# immutable). ``merimbula`` is a shallow coastal lake gridded at 10 m from a triangulation;
# ``lidar-dem`` is 1 m lidar terrain re-based as a seafloor 20 m below the surface. The
# ``repr`` gives the shape, cell size, extent, depth range and CRS.

lake = load("merimbula")
dem = load("lidar-dem")
print(lake)
print(dem)
print(f"merimbula: origin (northing, easting) = {lake.origin} in {lake.crs}; "
      f"{lake.valid_fraction:.0%} of its cells hold data")

# %%
# :func:`tangraph.plot.plot_map` draws a hill-shaded depth map on local north/east axes.
# Cells without data (the land around the lake) are left grey.

fig, axes = plt.subplots(1, 2, figsize=(11, 4.8), layout="constrained")
plot_map(lake, ax=axes[0])
plot_map(dem, ax=axes[1])
plt.show()

# %%
# Depth and gradient at points
# ----------------------------
#
# :meth:`~tangraph.maps.BathymetryMap.depth_at` takes ``north`` and ``east`` of any
# broadcastable shapes. A point off the map (or next to a no-data cell) gets NaN, never a value
# clamped to the edge; :meth:`~tangraph.maps.BathymetryMap.contains` says where there is data.
# :meth:`~tangraph.maps.BathymetryMap.gradient_at` returns ``(d depth / d north,
# d depth / d east)`` in a last axis of size 2.

north = np.array([100.0, 200.5, 350.0, -5.0])
east = np.array([100.0, 120.25, 390.0, 50.0])  # the last point lies south of the map
depth = dem.depth_at(north, east)
gradient = dem.gradient_at(north, east)
for n, e, d, g, inside in zip(north, east, depth, gradient, dem.contains(north, east),
                              strict=True):
    print(f"({n:7.2f}, {e:7.2f}) m: depth {d:7.3f} m, gradient ({g[0]:+.3f}, {g[1]:+.3f}),"
          f" on the map: {inside}")

# %%
# Bilinear and bicubic
# --------------------
#
# ``order=1`` (the default) interpolates bilinearly between the 2 x 2 cells around a point;
# ``order=3`` is bicubic (Keys, a = -0.5) on the 4 x 4 cells around it, with a continuous
# gradient. Along a profile through the 1 m lidar grid they differ by centimetres; the
# gradient shows the difference better: bilinear gradients jump at every cell edge.

profile_east = np.linspace(150.0, 160.0, 401)
profile_north = np.full_like(profile_east, 200.3)
fig, (ax_depth, ax_grad) = plt.subplots(2, 1, figsize=(8, 5.5), sharex=True,
                                        layout="constrained")
for order, label in ((1, "bilinear"), (3, "bicubic")):
    ax_depth.plot(profile_east, dem.depth_at(profile_north, profile_east, order=order),
                  label=label)
    ax_grad.plot(profile_east, dem.gradient_at(profile_north, profile_east, order=order)[:, 1],
                 label=label)
ax_depth.plot(dem.east[150:161], dem.depth_at(200.3, dem.east[150:161]), "k.",
              label="at cell centres")
ax_depth.set_ylabel("depth (m)")
ax_depth.invert_yaxis()
ax_depth.legend()
ax_grad.set_ylabel("d depth / d east")
ax_grad.set_xlabel("east (m) along north = 200.3 m")
plt.show()

difference = (dem.depth_at(profile_north, profile_east, order=3)
              - dem.depth_at(profile_north, profile_east, order=1))
print(f"largest bicubic - bilinear difference on the profile: {np.max(np.abs(difference)):.3f} m")

# %%
# Bicubic needs two cells on each side. Within one cell of the edge (or of a no-data cell) it
# falls back to bilinear, so both orders have data in exactly the same places:

edge = np.array([0.5, 398.5])  # half a cell inside the south and north edges
print("order 1:", dem.depth_at(edge, 200.0, order=1))
print("order 3:", dem.depth_at(edge, 200.0, order=3))

# %%
# Crop and resample
# -----------------
#
# :meth:`~tangraph.maps.BathymetryMap.crop` keeps the cells whose centres lie in a north/east
# range; :meth:`~tangraph.maps.BathymetryMap.resample` puts a map on a new cell size over the
# same extent (a coarser grid first averages the cells that fall in each new cell, so it is
# not aliased). Both return new maps; the original never changes.

basin = lake.crop(north=(1500.0, 3500.0), east=(1500.0, 4000.0))
coarse = basin.resample(50.0)
print(basin)
print(coarse)

fig, axes = plt.subplots(1, 2, figsize=(11, 4), layout="constrained")
plot_map(basin, ax=axes[0], title="merimbula, cropped (10 m cells)")
plot_map(coarse, ax=axes[1], title="resampled to 50 m cells")
plt.show()

# %%
# Terrain statistics
# ------------------
#
# :mod:`tangraph.maps.statistics` measures how much a map can tell a navigator. The slope
# (degrees) comes from the gradient of the interpolant at every cell centre; the roughness is
# the standard deviation of the depth about the best-fit plane of each window of cells (NaN
# where the window leaves the map or holds no-data).

window = 9
slope_deg = slope(dem)
rough = roughness(dem, window)
print(f"median slope {np.nanmedian(slope_deg):.1f} deg, "
      f"median roughness {np.nanmedian(rough):.3f} m ({window} x {window} cells)")

n_lo, n_hi, e_lo, e_hi = dem.extent
extent = (e_lo, e_hi, n_lo, n_hi)
fig, axes = plt.subplots(1, 2, figsize=(11, 4.5), layout="constrained")
for ax, values, label in ((axes[0], slope_deg, "slope (deg)"),
                          (axes[1], rough, f"roughness (m), {window} x {window} cells")):
    image = ax.imshow(values, origin="lower", extent=extent, cmap="magma")
    fig.colorbar(image, ax=ax, label=label, shrink=0.85)
    ax.set_xlabel("east (m)")
    ax.set_ylabel("north (m)")
    ax.set_title(f"lidar-dem: {label}")
plt.show()

# %%
# A mesh and a ray cast
# ---------------------
#
# :func:`~tangraph.maps.to_mesh` turns a map into an Open3D triangle mesh in the NED frame:
# vertices ``(north, east, depth)`` at cell centres, two triangles per grid square, squares
# with a no-data corner left out.

mesh = to_mesh(lake)
print(f"merimbula mesh: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles "
      f"({lake.shape[0]} x {lake.shape[1]} cells, {lake.valid_fraction:.0%} with data)")

# %%
# :func:`~tangraph.maps.raycasting_scene` puts the mesh in an Open3D ray-casting scene, and
# :func:`~tangraph.maps.cast_rays` returns the range along each ray to the seabed (``inf``
# where a ray misses). Cast straight down (direction ``(0, 0, 1)``, z is down) from 20 m above
# the surface at the centres of a few wet cells, the range minus 20 m is the depth there:
# the same as :meth:`~tangraph.maps.BathymetryMap.depth_at`. Between cell centres the mesh is
# linear on its triangles while ``depth_at`` is bilinear on the cells, so the two differ a
# little, and not at all on the grid.

scene = raycasting_scene(lake)
wet = np.isfinite(lake.depth)
square = wet[:-1, :-1] & wet[1:, :-1] & wet[:-1, 1:] & wet[1:, 1:]  # grid squares in the water
rows, cols = np.nonzero(square)
pick = np.linspace(0, rows.size - 1, 5).astype(int)
centres = np.column_stack([lake.north[rows[pick]], lake.east[cols[pick]]])
between = centres + 0.5 * np.array(lake.cell_size)  # the middle of a grid square
for label, points in (("cell centres", centres), ("between centres", between)):
    origins = np.column_stack([points, np.full(len(points), -20.0)])
    ray_depth = cast_rays(scene, origins, [0.0, 0.0, 1.0]) - 20.0
    print(f"{label}:")
    for (n, e), d_ray, d_map in zip(points, ray_depth, lake.depth_at(*points.T), strict=True):
        print(f"  ({n:6.1f}, {e:6.1f}) m: ray {d_ray:7.3f} m, depth_at {d_map:7.3f} m")

# %%
# Write and read back
# -------------------
#
# :func:`~tangraph.maps.write_map` picks the format from the suffix (NetCDF, GeoTIFF, XYZ,
# NPZ, or a PLY/OBJ mesh) and writes through a temporary file, so an interrupted write leaves
# no half file. Files written by tangraph say that depth is positive down, so they read back
# without options. Everything here goes to a temporary folder.

with tempfile.TemporaryDirectory() as folder:
    for suffix in (".nc", ".tif", ".npz"):
        path = write_map(basin, Path(folder) / f"basin{suffix}")
        back = read_map(path)
        same = np.allclose(back.depth, basin.depth, equal_nan=True, atol=1e-4)
        print(f"{path.name:<10} {path.stat().st_size:>8} bytes, reads back the same: {same}")
    mesh_path = write_map(basin, Path(folder) / "basin.ply")
    print(f"{mesh_path.name:<10} {mesh_path.stat().st_size:>8} bytes (a mesh of the basin)")

# %%
# Grid scattered soundings
# ------------------------
#
# Real surveys give scattered soundings, not grids. Here we simulate them from the lake map:
# random positions, the map's depth there plus 0.1 m of noise. Positions over land get NaN
# depth, as a sonar would get no return; :func:`~tangraph.maps.grid_soundings` drops those
# rows and counts them. Every random draw comes from one seeded generator.

rng = np.random.default_rng(1)
n_soundings = 100_000
sigma = 0.1
n_lo, n_hi, e_lo, e_hi = lake.extent
points_north = rng.uniform(n_lo, n_hi, n_soundings)
points_east = rng.uniform(e_lo, e_hi, n_soundings)
points_depth = lake.depth_at(points_north, points_east) + rng.normal(0.0, sigma, n_soundings)
soundings = np.column_stack([points_north, points_east, points_depth])

cell = 40.0  # cell centres on every 4th centre of the 10 m map, from its south-west corner
grid = grid_soundings(soundings, cell=cell, name="simulated soundings", crs=lake.crs,
                      origin=lake.origin, extent=lake.extent)
print(grid.mean)
print(f"{n_soundings} soundings, {grid.n_dropped} dropped (no depth); "
      f"{np.count_nonzero(grid.count)} of {grid.count.size} cells hold soundings, "
      f"median {np.median(grid.count[grid.count > 0]):.0f} per cell")

fig, axes = plt.subplots(1, 2, figsize=(11, 4.6), layout="constrained")
plot_map(grid.mean, ax=axes[0], title=f"mean depth of the soundings, {cell:g} m cells")
counts = np.where(grid.count > 0, grid.count, np.nan)
n0, n1, e0, e1 = grid.mean.extent
image = axes[1].imshow(counts, origin="lower", cmap="cividis",
                       extent=(e0 - cell / 2, e1 + cell / 2, n0 - cell / 2, n1 + cell / 2))
fig.colorbar(image, ax=axes[1], label="soundings per cell", shrink=0.85)
axes[1].set_title("count")
axes[1].set_xlabel("east (m)")
axes[1].set_ylabel("north (m)")
axes[1].set_aspect("equal")
plt.show()

# %%
# How close is the gridded mean to the map? The cell centres of the sounding grid are cell
# centres of the map, so we compare with the map's depth there, over the cells that hold at
# least 3 soundings. The difference has two parts: the noise, averaged over the few soundings
# of a cell, and the relief within a 40 m cell (soundings spread over a cell do not average to
# the depth at its centre, least of all on the steep shore). Gridding noise-free soundings at
# the same positions separates the two.

nn, ee = np.meshgrid(grid.mean.north, grid.mean.east, indexing="ij")
on_map = lake.depth_at(nn, ee)
good = (grid.count >= 3) & np.isfinite(on_map)
exact = grid_soundings(np.column_stack([points_north, points_east,
                                        lake.depth_at(points_north, points_east)]),
                       cell=cell, extent=lake.extent)


def rms(values: np.ndarray) -> float:
    """Root mean square over the compared cells."""
    return float(np.sqrt(np.mean(values[good] ** 2)))


print(f"{np.count_nonzero(good)} cells compared")
print(f"RMS difference, gridded soundings - map:            {rms(grid.mean.depth - on_map):.3f} m")
print(f"RMS difference, noise-free gridded soundings - map: {rms(exact.mean.depth - on_map):.3f} m")
print(f"noise of a cell's mean, sigma / sqrt(median count): "
      f"{sigma / np.sqrt(np.median(grid.count[good])):.3f} m")

# sphinx_gallery_thumbnail_number = 1
