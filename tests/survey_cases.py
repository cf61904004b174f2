"""A small survey with random poses and beams, some without a return and one ping without any,
shared by the survey tests and the CSV/XYZ import's."""

from __future__ import annotations

import numpy as np

from tangraph.survey import Survey


def make_survey(k=20, b=7, seed=0, truth=True):
    rng = np.random.default_rng(seed)
    time = np.cumsum(rng.uniform(0.5, 1.5, k))
    pose = np.column_stack(
        [np.cumsum(rng.normal(1, 0.1, k)), np.cumsum(rng.normal(0.5, 0.1, k)), rng.uniform(0, 2 * np.pi, k)]
    )
    depth = rng.uniform(40, 60, (k, b))
    depth[rng.random((k, b)) < 0.1] = np.nan
    depth[3] = np.nan  # an empty ping
    return Survey(
        time=time,
        dr_pose=pose,
        vehicle_depth=rng.uniform(5, 10, k),
        beam_forward=rng.normal(0, 1, (k, b)),
        beam_starboard=np.tile(np.linspace(-30, 30, b), (k, 1)),
        beam_depth=depth,
        true_pose=pose + rng.normal(0, 1, (k, 3)) if truth else None,
        meta={"map": "merimbula", "seed": seed, "sonar": {"n_beams": b}},
    )
