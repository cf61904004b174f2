"""A simulated survey as a recorder would give it: in another CRS (UTM 56S) with its own origin and
no word of the map it was simulated on; a navigation model (from the survey, and as a file's
text) and the horizontal RMSE of a track. Shared by the navigation, map-frame and ``smooth``
tests."""

from __future__ import annotations

import numpy as np

from tangraph.maps.grid import BathymetryMap
from tangraph.navigation import in_map_frame
from tangraph.sensors import NavigationModel

MODEL = "heading_bias_std_deg = 2.0\nspeed_scale_std = 0.02\nspeed_noise = 0.05\nsounding_std = 0.3\n"


def recorded(survey, crs="EPSG:32756", origin=(5_900_000.0, 230_000.0)):
    """The survey as a recorder would give it: in another CRS (UTM 56S: Merimbula lies 0.1 deg
    west of its edge) with its own origin, and no word of the map it was simulated on."""
    frame = BathymetryMap(north=np.array([0.0, 1.0]), east=np.array([0.0, 1.0]), depth=np.zeros((2, 2)),
                          crs=crs, origin=origin, name="frame")
    moved = in_map_frame(survey, frame)
    meta = {k: v for k, v in moved.meta.items() if k not in ("map", "map_identity", "reprojected_from")}
    return moved.replace(meta=meta)


def model_for(survey):
    return NavigationModel.from_survey(survey)


def horizontal_rmse(pose, truth):
    return float(np.sqrt(np.mean(np.sum((pose[:, :2] - truth[:, :2]) ** 2, axis=1))))
