"""Sensors: the dead-reckoning (INS/DVL) error model and multibeam / single-beam sonar."""

from tangraph.sensors.dead_reckoning import (
    DeadReckoning,
    DeadReckoningModel,
    increment_covariance,
    odometry,
    rotation_matrix,
    simulate_dead_reckoning,
    walk_variance,
)
from tangraph.sensors.matern import matern_correlation, matern_field
from tangraph.sensors.misfit import MisfitScale, misfit_counts
from tangraph.sensors.navigation_model import (
    KNOWN_STD,
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
from tangraph.sensors.terrain import (
    MapError,
    information_exponent,
    map_error,
    map_error_grids,
    placed_map_variances,
    shared_among,
    shared_map_variances,
    shared_quadratic,
    slope_moment,
    sounding_map_counts,
    sounding_map_variances,
    sounding_variances,
    survey_map_error,
)

__all__ = [
    "KNOWN_STD",
    "DeadReckoning",
    "DeadReckoningModel",
    "MapError",
    "MisfitScale",
    "MultibeamConfig",
    "NavigationModel",
    "Pings",
    "SingleBeamConfig",
    "beam_angles",
    "increment_covariance",
    "information_exponent",
    "load_navigation_model",
    "map_error",
    "map_error_grids",
    "matern_correlation",
    "matern_field",
    "misfit_counts",
    "odometry",
    "placed_map_variances",
    "rotation_matrix",
    "shared_among",
    "shared_map_variances",
    "shared_quadratic",
    "simulate_dead_reckoning",
    "simulate_pings",
    "slope_moment",
    "sounding_map_counts",
    "sounding_map_variances",
    "sounding_variances",
    "survey_map_error",
    "survey_navigation_model",
    "walk_variance",
]
