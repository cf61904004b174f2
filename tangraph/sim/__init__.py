"""Trajectories and scenarios that produce simulated surveys."""

from tangraph.sim.scenario import (
    Scenario,
    ScenarioError,
    list_scenarios,
    load_dr_model,
    load_scenario,
    simulate,
)
from tangraph.sim.trajectories import lawnmower, straight_line, waypoint_route

__all__ = [
    "Scenario",
    "ScenarioError",
    "lawnmower",
    "list_scenarios",
    "load_dr_model",
    "load_scenario",
    "simulate",
    "straight_line",
    "waypoint_route",
]
