"""A small simulated survey on a rough synthetic map, and spoilt surveys (a biased DR, a DR started
far off), shared by the graph tests."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from tangraph.maps import fractal
from tangraph.sensors import DeadReckoningModel, MultibeamConfig
from tangraph.sim.faults import offset_start
from tangraph.sim.scenario import Scenario, simulate


def small_scenario(duration: float = 400.0, **dr) -> Scenario:
    model = DeadReckoningModel(**{"heading_bias": float(np.deg2rad(1.0)), "speed_scale": 0.01,
                                  "speed_noise": 0.05, "start_position_std": 10.0, **dr})
    return Scenario(
        name="graph-test",
        map="fractal",
        seed=6,
        vehicle_depth=5.0,
        trajectory={"kind": "line", "start": [300.0, 300.0], "heading_deg": 45.0, "speed": 2.0,
                    "duration": duration},
        dead_reckoning=model,
        sonar=MultibeamConfig(n_beams=40, swath=float(np.deg2rad(120.0)), ping_rate=0.5, depth_noise=0.2),
    )


@pytest.fixture(scope="session")
def rough_map():
    return fractal((300, 300), 5.0, rng=np.random.default_rng(60), beta=3.0, relief=15.0, mean_depth=60.0)


@pytest.fixture(scope="session")
def small_survey(rough_map):
    return simulate(small_scenario(), rng=np.random.default_rng(61), bathymetry=rough_map, seed=61)


def with_dr(scenario: Scenario, **changes) -> Scenario:
    model = dataclasses.replace(scenario.dead_reckoning, **changes)
    return dataclasses.replace(scenario, dead_reckoning=model)


@pytest.fixture(scope="module")
def biased_survey(rough_map):
    from tangraph.sim.scenario import simulate

    scenario = small_scenario(duration=800.0, heading_bias=float(np.deg2rad(3.0)), speed_scale=0.03)
    return simulate(scenario, rng=np.random.default_rng(100), bathymetry=rough_map, seed=100)


@pytest.fixture(scope="module")
def wrong_start(small_survey):
    """The DR starts 120 m from the truth while the model says 10 m (std)."""
    return offset_start(small_survey, [90.0, -80.0])
