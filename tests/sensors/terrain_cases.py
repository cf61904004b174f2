"""A flat map and scattered soundings for the terrain model's tests."""

import numpy as np

from tangraph.maps import BathymetryMap
from tangraph.survey import Survey

FLAT = BathymetryMap(np.arange(0.0, 1000, 10), np.arange(0.0, 1000, 10), np.full((100, 100), 30.0))


def scattered_survey(points: np.ndarray) -> Survey:
    """One sounding per ping at ``points (K, 2)`` (the vehicle over each)."""
    k = points.shape[0]
    pose = np.column_stack([points, np.zeros(k)])
    t = np.arange(float(k))
    return Survey(time=t, dr_pose=pose, vehicle_depth=0 * t, beam_forward=np.zeros((k, 1)),
                  beam_starboard=np.zeros((k, 1)), beam_depth=np.full((k, 1), 30.0))
