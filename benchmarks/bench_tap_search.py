"""Speed of the TAP criterion search (tangraph.matching.search.criterion_sums).

    ./run bench   (or: python benchmarks/bench_tap_search.py [--repeat R] [--skip-numpy-large]);
    one thread: NUMBA_NUM_THREADS and OMP_NUM_THREADS default to 1.

A 1000 x 1000 map (5 m cells, fractal relief); patches of pings x 60 beams (10 m between pings,
120 m swath, heading 30 deg); whole-cell candidate grids (step 5 m) of 201 x 201 x 600 soundings
(the target: at most 50 ms on one core) and 401 x 401 x 3000, plus a sub-cell step (3.7 m,
the general direct kernel) and a 3-heading whole-cell search. Each case times the direct and FFT
paths, what "auto" picks, and a plain-numpy search (vectorised over the candidates for each
sounding) in the same run, best of R, and prints ms and ratios. Nothing here is asserted.
"""

from __future__ import annotations

import argparse
import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np
from _timing import best_time

from tangraph.maps import BathymetryMap, fractal
from tangraph.matching.search import CandidateGrid, criterion_sums

CELL = 5.0


def patch(pings: int, beams: int = 60, heading: float = np.radians(30.0)):
    along = (np.arange(pings) - pings + 1) * 10.0
    across = np.linspace(-60.0, 60.0, beams)
    a, c = np.meshgrid(along, across, indexing="ij")
    return np.column_stack([
        (a * np.cos(heading) - c * np.sin(heading)).ravel(),
        (a * np.sin(heading) + c * np.cos(heading)).ravel(),
    ])


def numpy_search(bathymetry: BathymetryMap, offsets, depths, grid: CandidateGrid) -> np.ndarray:
    """sum_d2 by plain numpy: for each sounding, bilinear depths at all candidates at once."""
    nn, ee = np.meshgrid(grid.north, grid.east, indexing="ij")
    dn, de = bathymetry.cell_size
    ny, nx = bathymetry.shape
    total = np.zeros(nn.shape)
    for (o_n, o_e), z in zip(offsets, depths, strict=True):
        fy = (nn + o_n - bathymetry.north[0]) / dn
        fx = (ee + o_e - bathymetry.east[0]) / de
        inside = (fy >= 0) & (fy <= ny - 1) & (fx >= 0) & (fx <= nx - 1)
        i = np.clip(np.floor(fy).astype(np.int64), 0, ny - 2)
        j = np.clip(np.floor(fx).astype(np.int64), 0, nx - 2)
        ty, tx = fy - i, fx - j
        dep = bathymetry.depth
        h = ((1 - ty) * ((1 - tx) * dep[i, j] + tx * dep[i, j + 1])
             + ty * ((1 - tx) * dep[i + 1, j] + tx * dep[i + 1, j + 1]))  # fmt: skip
        total += np.where(inside, h - z, np.nan) ** 2
    return total


def best_ms(fn, repeat: int) -> float:
    return 1e3 * best_time(fn, repeat)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    parser.add_argument("--skip-numpy-large", action="store_true", help="no numpy run of 401 x 401")
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    m = fractal((1000, 1000), CELL, rng=rng, beta=3.0, relief=10.0, mean_depth=100.0, name="bench")
    centre = (2500.0, 2500.0)
    cases = [
        ("201 x 201 x 600, step 5 m", CandidateGrid.around(centre, 500.0, CELL), 10),
        ("401 x 401 x 3000, step 5 m", CandidateGrid.around(centre, 1000.0, CELL), 50),
        ("201 x 201 x 600, 3 headings", CandidateGrid.around(centre, 500.0, CELL, [-0.05, 0.0, 0.05]), 10),
        ("201 x 201 x 600, step 3.7 m", CandidateGrid.around(centre, 370.0, 3.7), 10),
    ]
    print(f"criterion_sums on a 1000 x 1000 map ({CELL:g} m cells), best of {args.repeat}, "
          f"NUMBA_NUM_THREADS={os.environ['NUMBA_NUM_THREADS']}, pid {os.getpid()}")
    print(f"{'case':<30}{'direct ms':>10}{'fft ms':>9}{'auto':>8}{'numpy ms':>10}"
          f"{'numpy/direct':>13}{'numpy/fft':>10}{'ns/cand/snd':>12}")
    for label, grid, pings in cases:
        offsets = patch(pings)
        truth = np.add(centre, (35.0, -20.0))
        depths = m.depth_at(truth[0] + offsets[:, 0], truth[1] + offsets[:, 1]) + 1.5
        depths += 0.1 * rng.normal(size=depths.size)

        def run(method, g=grid, o=offsets, z=depths):
            return criterion_sums(m, o, z, g, method=method)

        t_direct = best_ms(lambda: run("direct"), args.repeat)
        try:
            t_fft = best_ms(lambda: run("fft"), args.repeat)
        except ValueError:
            t_fft = float("nan")
        auto = run("auto").method
        work = grid.size * offsets.shape[0]
        if (args.skip_numpy_large and work > 1e8) or grid.shape[0] > 1:
            t_np = float("nan")
        else:
            t_np = best_ms(lambda g=grid, o=offsets, z=depths: numpy_search(m, o, z, g), 1)
        print(f"{label:<30}{t_direct:>10.1f}{t_fft:>9.1f}{auto:>8}{t_np:>10.0f}"
              f"{t_np / t_direct:>12.0f}x{t_np / t_fft:>9.0f}x{1e6 * t_direct / work:>12.2f}")


if __name__ == "__main__":
    main()
