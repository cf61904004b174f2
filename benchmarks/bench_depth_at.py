"""Throughput of BathymetryMap.depth_at / gradient_at against the plain-numpy reference.

    ./run bench            (or: python benchmarks/bench_depth_at.py [--points N] [--repeat R])

10^6 query points on a 1000 x 1000 map (5 m cells), clustered (a particle cloud: 20 m std
around one point) and random (uniform over the map), one core. Prints samples per second and
the ratio to the numpy reference of the tests (vectorised gathers; bicubic always computes its
gradient too) measured in the same run. Nothing here is asserted.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # for tests.maps.reference

from _timing import best_time

from tangraph.maps import BathymetryMap
from tests.maps.reference import interpolate as numpy_reference


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=1_000_000)
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    n = args.points
    m = BathymetryMap(north=np.arange(1000) * 5.0, east=np.arange(1000) * 5.0,
                      depth=100 + rng.normal(size=(1000, 1000)).cumsum(axis=0) * 0.1, name="bench")
    clouds = {
        "clustered": 2500 + rng.normal(0, 20, (2, n)),
        "random": rng.uniform(0, 4995, (2, n)),
    }
    print(f"depth_at on a 1000 x 1000 map, {n:,} points, best of {args.repeat}, "
          f"pid {os.getpid()}, one thread")
    print(f"{'query':<22}{'points':<11}{'tangraph (M/s)':>15}{'numpy ref (M/s)':>17}{'ratio':>8}")
    for cloud, (qn, qe) in clouds.items():
        for label, order, grad in (("bilinear", 1, False), ("bicubic", 3, False),
                                   ("bilinear + gradient", 1, True), ("bicubic + gradient", 3, True)):
            query = m.gradient_at if grad else m.depth_at
            t_fast = best_time(lambda q=query, a=qn, b=qe, o=order: q(a, b, order=o), args.repeat)
            t_ref = best_time(
                lambda a=qn, b=qe, o=order, g=grad: numpy_reference(m.north, m.east, m.depth, a, b, o, g),
                max(1, args.repeat // 2),
            )
            print(f"{label:<22}{cloud:<11}{n / t_fast / 1e6:>15.1f}{n / t_ref / 1e6:>17.2f}"
                  f"{t_ref / t_fast:>7.0f}x")


if __name__ == "__main__":
    main()
