"""Trajectories and scenarios that produce simulated surveys."""

from tangraph.sim.trajectories import lawnmower, straight_line, waypoint_route

__all__ = ["lawnmower", "straight_line", "waypoint_route"]
