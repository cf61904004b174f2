"""Sensors: the dead-reckoning (INS/DVL) error model and multibeam / single-beam sonar."""

from tangraph.sensors.dead_reckoning import (
    DeadReckoning,
    DeadReckoningModel,
    increment_covariance,
    odometry,
    rotation_matrix,
    simulate_dead_reckoning,
)
from tangraph.sensors.navigation_model import (
    NavigationModel,
    load_navigation_model,
    survey_navigation_model,
)
from tangraph.sensors.sonar import (
    MultibeamConfig,
    Pings,
    SingleBeamConfig,
    beam_angles,
    simulate_pings,
)

__all__ = [
    "DeadReckoning",
    "DeadReckoningModel",
    "MultibeamConfig",
    "NavigationModel",
    "Pings",
    "SingleBeamConfig",
    "beam_angles",
    "increment_covariance",
    "load_navigation_model",
    "odometry",
    "rotation_matrix",
    "simulate_dead_reckoning",
    "simulate_pings",
    "survey_navigation_model",
]
