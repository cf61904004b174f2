"""The runner's recovery policy on a step that diverges or finds no map at chosen pings."""

from __future__ import annotations

import re

import numpy as np

from tangraph.filters import FilterDivergence, FilterHealth, OffMap, PFConfig
from tangraph.filters.pf import pf_step
from tangraph.filters.runner import run_particle_filter
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0, shape=(100, 100))
SURVEY = multibeam_survey(MAP, pings=12)
MODEL = navigation(SURVEY, initial_position_std=10.0, sounding_std=0.5)


def failing_at(diverged, off_map):
    def step(belief, ping, model, config, *, rng):
        if ping.index in diverged:
            raise FilterDivergence(f"ping {ping.index}: made to diverge")
        if ping.index in off_map:
            raise OffMap(f"ping {ping.index}: made off the map")
        return pf_step(belief, ping, model, config, rng=rng)

    return step


def test_divergences_in_a_row_widen_the_fresh_cloud_up_to_the_map_and_off_map_pings_only_predict(caplog):
    config = PFConfig(n_particles=200, health=FilterHealth(reinit_std=40.0, reinit_growth=4.0))
    step = failing_at(diverged=(2, 3, 4, 5, 8), off_map=(6, 10))
    with caplog.at_level("WARNING", logger="tangraph.filters.runner"):
        track = run_particle_filter(SURVEY, MAP, config, step, method="pf", model=MODEL,
                                    rng=np.random.default_rng(3))
    pattern = re.compile(r"re-initialised around dead reckoning, spread ([0-9.]+) m")
    spreads = [float(m.group(1)) for r in caplog.records if (m := pattern.search(r.getMessage()))]
    n_min, n_max, e_min, e_max = MAP.extent
    diagonal = float(np.hypot(n_max - n_min, e_max - e_min))
    # 40, 160, 640, then the cap; an off-map ping does not end the run of divergences, a step does
    assert spreads == [40.0, 160.0, 640.0, round(diagonal, 1), 40.0]
    assert track.meta["divergence_steps"] == [2, 3, 4, 5, 8]
    assert track.meta["off_map_steps"] == [6, 10]
    assert track.meta["n_divergences"] == 5 and track.meta["n_off_map"] == 2
    assert any("2 pings off the map (first 6)" in r.getMessage() for r in caplog.records)
    assert np.all(np.isfinite(track.pose)) and np.all(np.isfinite(track.covariance[:, :2, :2]))
    assert list(track.meta)[:10] == [
        "ess", "n_resampled", "n_divergences", "divergence_steps", "n_lost", "lost_steps", "n_off_map",
        "off_map_steps", "n_redraws", "redraw_steps",
    ]
