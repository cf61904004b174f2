"""Terrain and straight runs for the TAP tests: a rough fractal map, and a run whose soundings are
sampled from a map plus a tide and noise, its DR the truth plus an offset."""

from __future__ import annotations

import numpy as np

from tangraph.maps import fractal
from tangraph.survey import Survey, footprints

CELL = 5.0


def rough_map(seed=0):
    return fractal((300, 300), CELL, rng=np.random.default_rng(seed), beta=3.0, relief=5.0, mean_depth=80.0)


def survey_on(
    bathymetry,
    *,
    offset=(15.0, -10.0),
    noise=0.0,
    tide=1.5,
    seed=0,
    pings=10,
    beams=41,
    start=(500.0, 400.0),
    heading=np.pi / 2,
    spacing=5.0,
):
    """Soundings of a straight run sampled from the map itself; DR = truth + ``offset``."""
    rng = np.random.default_rng(seed)
    k = np.arange(pings)
    truth = np.column_stack(
        [
            start[0] + k * spacing * np.cos(heading),
            start[1] + k * spacing * np.sin(heading),
            np.full(pings, heading),
        ]
    )
    forward = np.zeros((pings, beams))
    starboard = np.tile(np.linspace(-60, 60, beams), (pings, 1))
    north, east = footprints(truth, forward, starboard)
    depth = bathymetry.depth_at(north, east) + tide + noise * rng.normal(size=forward.shape)
    dr = truth + np.array([*offset, 0.0])
    return Survey(
        time=k.astype(float),
        dr_pose=dr,
        vehicle_depth=np.full(pings, 10.0),
        beam_forward=forward,
        beam_starboard=starboard,
        beam_depth=depth,
        true_pose=truth,
    )
