"""A tilted plane and a rough random-walk map with NaN holes, shared by the BathymetryMap tests and
the interpolation kernels'."""

from __future__ import annotations

import numpy as np

from tangraph.maps import BathymetryMap


def plane(a=100.0, gn=0.1, ge=-0.05, shape=(20, 30), cell=(5.0, 4.0)):
    north = 10.0 + cell[0] * np.arange(shape[0])
    east = -50.0 + cell[1] * np.arange(shape[1])
    nn, ee = np.meshgrid(north, east, indexing="ij")
    return BathymetryMap(north=north, east=east, depth=a + gn * nn + ge * ee, name="plane")


def rough(seed=0, shape=(60, 50), nan_fraction=0.02):
    rng = np.random.default_rng(seed)
    depth = 50 + rng.normal(size=shape).cumsum(axis=0).cumsum(axis=1) * 0.1
    depth[rng.random(shape) < nan_fraction] = np.nan
    return BathymetryMap(north=np.arange(shape[0]) * 2.0, east=100 + np.arange(shape[1]) * 3.0,
                         depth=depth)
