"""Gridding a TIN: linear interpolation (matplotlib.tri) against Open3D ray casting.

    python benchmarks/bench_tin.py [--cells 10 5 2]

The shipped Merimbula TIN (5719 vertices) gridded by :func:`tangraph.maps.mesh.triangles_to_map`
with ``method="linear"`` and, as the reference measured in the same run, ``method="raycast"``;
prints both times, their ratio, the largest depth difference and the centres where only one of
them has data. Nothing is asserted.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from _timing import best_time

from tangraph.maps.io import read_tsh
from tangraph.maps.mesh import triangles_to_map


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=float, nargs="+", default=[10.0, 5.0, 2.0])
    args = parser.parse_args()
    verts, tris, _ = read_tsh(Path(__file__).resolve().parents[1] / "maps" / "merimbula_10785_1.tsh")
    v = np.column_stack([verts[:, 1] - verts[:, 1].min(), verts[:, 0] - verts[:, 0].min(), -verts[:, 2]])
    for cell in args.cells:
        linear = triangles_to_map(v, tris, cell=cell, method="linear")
        ray = triangles_to_map(v, tris, cell=cell, method="raycast")
        t_lin = best_time(lambda cell=cell: triangles_to_map(v, tris, cell=cell, method="linear"), 3)
        t_ray = best_time(lambda cell=cell: triangles_to_map(v, tris, cell=cell, method="raycast"), 3)
        a, b = np.isfinite(linear.depth), np.isfinite(ray.depth)
        diff = float(np.max(np.abs(linear.depth - ray.depth)[a & b]))
        print(f"cell {cell:4g} m, {linear.depth.size:>9} centres: linear {t_lin:.3f} s, "
              f"raycast {t_ray:.3f} s (ratio {t_ray / t_lin:.1f}); max |diff| {diff:.2e} m; "
              f"data in one only: {int((a != b).sum())}")


if __name__ == "__main__":
    main()
