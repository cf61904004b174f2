"""Surveys and seabeds with known answers for the terrain solve's tests: a textured map, a
three-leg lawnmower, noise-free soundings."""

import numpy as np

from tangraph.maps import BathymetryMap
from tangraph.survey import Survey

AXIS = np.arange(0.0, 400.0, 2.0)


def smooth_map(slope=(0.0, 0.0), wavy=1.0) -> BathymetryMap:
    n, e = AXIS[:, None], AXIS[None, :]
    relief = 3.0 * np.sin(n / 23.0) * np.cos(e / 31.0) + np.sin(e / 11.0)
    depth = 50.0 + slope[0] * n + slope[1] * e + wavy * relief
    return BathymetryMap(AXIS, AXIS, depth)


def lawnmower(n_pings=240, start_error=(6.0, 0.0)):
    """Three east-going legs 40 m apart, a ping every 2 m, 11 beams across; the DR is the truth
    shifted by ``start_error`` (north, east) with exact increments."""
    legs = []
    for leg in range(3):
        east = np.arange(n_pings // 3) * 2.0
        along = (east if leg % 2 == 0 else east[::-1]) + 80.0
        heading = np.full(east.size, np.pi / 2 if leg % 2 == 0 else -np.pi / 2)
        legs.append(np.column_stack([100.0 + 40.0 * leg + 0 * east, along, heading]))
    truth = np.concatenate(legs)
    k = truth.shape[0]
    beams = np.linspace(-20.0, 20.0, 11)
    return truth, Survey(time=np.arange(float(k)), dr_pose=truth + np.array([*start_error, 0.0]),
                         vehicle_depth=np.zeros(k), beam_forward=np.zeros((k, beams.size)),
                         beam_starboard=np.tile(beams, (k, 1)), beam_depth=np.zeros((k, beams.size)),
                         true_pose=truth)


def noise_free(survey, bathymetry):
    north, east = survey.footprints(survey.true_pose)
    return survey.replace(beam_depth=bathymetry.depth_at(north, east))
