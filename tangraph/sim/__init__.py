"""Trajectories and scenarios that produce simulated surveys."""

from tangraph.sim.scenario import (
    Scenario,
    ScenarioError,
    Simulation,
    list_scenarios,
    load_dr_model,
    load_scenario,
    simulate,
    simulate_run,
)
from tangraph.sim.seafloor import PriorMapSettings, ScenarioWorld, SeafloorSettings, simulate_world
from tangraph.sim.trajectories import lawnmower, straight_line, waypoint_route

__all__ = [
    "PriorMapSettings",
    "Scenario",
    "ScenarioError",
    "ScenarioWorld",
    "SeafloorSettings",
    "Simulation",
    "lawnmower",
    "list_scenarios",
    "load_dr_model",
    "load_scenario",
    "simulate",
    "simulate_run",
    "simulate_world",
    "straight_line",
    "waypoint_route",
]
