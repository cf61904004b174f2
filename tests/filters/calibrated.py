"""Runs from a DR 3 % fast and turned 3 deg over a rough map of 300 x 300 cells, shared by the tests
of the filters' calibration (the speed scale and heading bias they estimate)."""

from __future__ import annotations

import numpy as np

from tangraph.sensors import DeadReckoningModel
from tests.filters.synthetic import multibeam_survey, rough_map

MAP = rough_map(0, shape=(300, 300))
DR = DeadReckoningModel(speed_scale=0.03, heading_bias=np.radians(3.0), speed_noise=0.05)


def calibrated_survey(seed, pings=80):
    """80 pings of 30 beams (800 m) from a DR reading 3 % fast and turned 3 deg clockwise."""
    return multibeam_survey(MAP, seed=seed, pings=pings, dr_model=DR, start=(300.0, 300.0), heading_deg=45.0)
