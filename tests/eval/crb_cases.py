"""The turning survey over a planar seabed, and its navigation model, of the Cramér-Rao bound
tests (with the map's error field and without)."""

from __future__ import annotations

import numpy as np

from tangraph.maps import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.sensors.dead_reckoning import walk_variance
from tangraph.survey import Survey

SLOPE = (0.04, -0.03)  # d depth / d north, d depth / d east


def _seabed(slope=SLOPE, east_end=800.0) -> BathymetryMap:
    north = np.arange(0.0, 1001.0, 10.0)
    east = np.arange(0.0, east_end + 1.0, 10.0)
    depth = 30.0 + slope[0] * north[:, None] + slope[1] * east[None, :]
    return BathymetryMap(north=north, east=east, depth=depth, name="plane")


def _truth(k: int = 40) -> tuple[np.ndarray, np.ndarray]:
    """A turning track (uneven sampling, sideslip) that runs off the east edge of ``_seabed``."""
    t = np.cumsum(np.r_[0.0, 2.0 + 0.5 * np.sin(np.arange(k - 1))])
    psi = 0.4 + 0.03 * t
    course = psi + 0.05
    dt = np.diff(t)
    north = 400.0 + np.r_[0.0, np.cumsum(2.0 * np.cos(course[:-1]) * dt)]
    east = 700.0 + np.r_[0.0, np.cumsum(2.0 * np.sin(course[:-1]) * dt)]
    return t, np.column_stack([north, east, psi])


def _survey(k: int = 40, beams: int = 7, *, rng_seed: int = 3, width: float = 40.0) -> Survey:
    t, truth = _truth(k)
    rng = np.random.default_rng(rng_seed)
    starboard = np.tile(np.linspace(-width, width, beams), (k, 1))
    forward = 3.0 * np.sin(starboard / 7.0)
    depth = 30.0 + rng.normal(size=(k, beams))
    depth[rng.random((k, beams)) < 0.15] = np.nan  # beams without a return
    depth[5] = np.nan  # an empty ping
    return Survey(time=t, dr_pose=truth, vehicle_depth=np.zeros(k), beam_forward=forward,
                  beam_starboard=starboard, beam_depth=depth, true_pose=truth)


MODEL = NavigationModel(speed_noise=0.1, heading_noise=0.01, heading_walk=0.002, speed_scale_std=0.02,
                        heading_bias_std=0.03, initial_position_std=5.0, sounding_std=0.3, tide_std=0.5)
FIELD = MODEL.replace(map_std=0.3, map_correlation_length=60.0)  # a map error of 0.3 m over 60 m


def _jd(d: np.ndarray) -> np.ndarray:
    return np.column_stack([-d[:, 1], d[:, 0]])


def _soundings(survey: Survey, seabed: BathymetryMap):
    """Mask of the soundings that count, and their heading features ``g . J r`` (plane: g fixed)."""
    truth = survey.true_pose
    north, east = survey.footprints(truth)
    used = np.isfinite(survey.beam_depth) & seabed.contains(north, east)
    g = np.array(SLOPE)
    turn = g[1] * (north - truth[:, :1]) - g[0] * (east - truth[:, 1:2])
    return used, turn


def _design(survey: Survey, model: NavigationModel):
    """The dense linear model of the DR errors over its independent inputs (dp0, s, b, tide | v_n,
    v_e, u per interval | n per ping): ping k's error is ``a[k] @ theta``, its heading error
    ``e[k] @ theta``; with the tide's row and the inputs' prior variances."""
    t, truth = survey.time, survey.true_pose
    k = t.size
    d, dt = np.diff(truth[:, :2], axis=0), np.diff(t)
    var = [model.initial_position_std**2] * 2 + list(model.calibration_std**2) + [model.tide_std**2]
    turned = np.angle(np.exp(1j * np.diff(truth[:, 2])))
    walk = walk_variance(model.heading_walk, model.heading_turn_std, dt, turned)
    var += list(np.column_stack([(model.speed_noise * dt) ** 2] * 2 + [walk]).ravel())
    var += [model.heading_noise**2] * k
    eye = np.eye(len(var))
    white = 5 + 3 * (k - 1)
    dp, walk = eye[:2].copy(), np.zeros(len(var))
    a, e = [dp], [eye[3] + eye[white]]
    for m in range(k - 1):
        dp = dp + np.outer(d[m], eye[2]) + np.outer(_jd(d[m:m + 1])[0], e[-1]) + eye[5 + 3 * m:7 + 3 * m]
        walk = walk + eye[7 + 3 * m]
        a.append(dp)
        e.append(eye[3] + walk + eye[white + m + 1])
    return np.array(a), np.array(e), eye[4], np.array(var)
