"""Small synthetic surveys with a known truth for the filter tests (no ray casting: the soundings
are the map's bilinear depth at the true footprints plus seeded noise), and a bare fix."""

from __future__ import annotations

import dataclasses
import types

import numpy as np

from tangraph.maps import BathymetryMap, fractal
from tangraph.sensors import DeadReckoningModel, NavigationModel, simulate_dead_reckoning
from tangraph.sim import trajectories
from tangraph.survey import Survey, footprints


def rough_map(seed: int = 0, *, shape=(200, 200), cell: float = 5.0, relief: float = 8.0) -> BathymetryMap:
    return fractal(shape, cell, rng=np.random.default_rng(seed), beta=3.0, relief=relief, mean_depth=80.0)


def multibeam_survey(
    bathymetry: BathymetryMap,
    *,
    seed: int = 0,
    pings: int = 60,
    beams: int = 30,
    swath: float = 80.0,
    start=(200.0, 150.0),
    heading_deg: float = 60.0,
    speed: float = 2.0,
    rate: float = 0.2,
    noise: float = 0.3,
    tide: float = 0.0,
    dr_model: DeadReckoningModel | None = None,
) -> Survey:
    """A straight run with a drifting dead reckoning (3 deg heading bias by default); its
    ``meta["settings"]`` records the DR model and the depth noise, as a simulated survey's do
    (so ``NavigationModel.from_survey`` works on it)."""
    rng = np.random.default_rng(seed)
    time, truth = trajectories.straight_line(
        np.asarray(start, float), np.radians(heading_deg), speed, (pings - 1) / rate, rate
    )
    model = dr_model or DeadReckoningModel(heading_bias=np.radians(3.0), speed_noise=0.05)
    dr = simulate_dead_reckoning(time, truth, model, rng=rng).pose
    k = time.size
    forward = np.zeros((k, beams))
    starboard = np.tile(np.linspace(-swath / 2, swath / 2, beams), (k, 1))
    north, east = footprints(truth, forward, starboard)
    depth = bathymetry.depth_at(north, east) + tide + noise * rng.standard_normal(north.shape)
    return Survey(
        time=time,
        dr_pose=dr,
        vehicle_depth=np.full(k, 10.0),
        beam_forward=forward,
        beam_starboard=starboard,
        beam_depth=depth,
        true_pose=truth,
        meta={"settings": {"dead_reckoning": dataclasses.asdict(model), "sonar": {"depth_noise": noise}}},
    )


def navigation(survey: Survey, **overrides) -> NavigationModel:
    """The navigation model of a synthetic survey (``overrides`` replace fields)."""
    return NavigationModel.from_survey(survey, **overrides)


def final_error(track, survey: Survey) -> float:
    return float(np.hypot(*(track.pose[-1, :2] - survey.true_pose[-1, :2])))


def dr_final_error(survey: Survey) -> float:
    return float(np.hypot(*(survey.dr_pose[-1, :2] - survey.true_pose[-1, :2])))


def gaussian_fix(position, std):
    """What :func:`~tangraph.filters.fixes.decide_fix` reads of a fix."""
    return types.SimpleNamespace(position=np.asarray(position, float), covariance=np.eye(2) * std**2)
