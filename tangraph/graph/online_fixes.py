"""The online navigator's window fixes: made on the prediction, weighed for the graph, judged.

At a window end the :class:`~tangraph.graph.GraphNavigator` makes the window's fix (TAP, or the
point-mass front end of :mod:`tangraph.graph.posterior_fix` with the graph's belief in the tide)
centred on its prediction, grows its covariance by what is uncertain of the calibrated patch
(:func:`grown`), and judges it against the prediction and the residual std of the windows around
it (:func:`judge`, :func:`misfit_noise`); what it then does with the fix is the fix policy's
(:mod:`tangraph.graph.lost`). The functions read and update the navigator's state (its fix timings
and the last windows' residual stds), as :mod:`tangraph.graph.lost`'s do.
"""

from __future__ import annotations

import logging
import time as _time
from typing import TYPE_CHECKING

import gtsam
import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.likelihood import TerrainLikelihood
from tangraph.graph import online_tide
from tangraph.graph.calibration import position_tide_factor, to_world, world_jacobian
from tangraph.graph.factors import check_fix_covariance, compose, propagate_joint
from tangraph.graph.fixes import (
    FixOutcome,
    FixStatus,
    failed,
    fix_name,
    judge_fix,
    make_fix,
    search_half_width,
    window_noise,
)
from tangraph.graph.posterior_fix import GRID_SIGMAS, WindowFix, posterior_fix
from tangraph.matching import MatchingError, window_patch
from tangraph.sensors import (
    map_error,
    odometry,
    placed_map_variances,
    slope_moment,
    sounding_map_counts,
    sounding_variances,
)

if TYPE_CHECKING:
    from tangraph.graph.online import GraphNavigator
    from tangraph.maps.grid import BathymetryMap
    from tangraph.matching import TerrainFix
    from tangraph.sensors import NavigationModel
    from tangraph.survey import Survey

__all__ = ["MISFIT_WINDOWS", "TIDE_STEP_AGREE", "TIDE_STEP_PINGS", "fix_factor", "grow_window", "grown",
           "judge", "laid_poses", "misfit_noise", "position_tide_prior", "posterior_window_fix", "tide_step",
           "window_terrain", "window_variances"]

log = logging.getLogger("tangraph.graph.online")  # the navigator's messages, one logger for them
#: The tide steps when the point-mass front end's windows find one depth fault (offsets within
#: ``TIDE_STEP_AGREE`` m of each other) over ``TIDE_STEP_PINGS`` pings in a row: longer than a
#: block of bad pings should last (the robustness study's are 20 pings).
TIDE_STEP_PINGS = 40
TIDE_STEP_AGREE = 1.0

MISFIT_WINDOWS = 10  #: windows whose median residual std the misfit test may compare to


def judge(nav: GraphNavigator, k: int, pose, joint, fix: TerrainFix | None,
          strict: bool = False) -> FixOutcome:
    """The fix of the window ending at ping ``k`` (DR-frame ``pose``, ``joint`` covariance with
    the calibration), made on the prediction (TAP or the point-mass front end) unless ``fix`` is
    given, its covariance grown for the graph (:func:`grown`) and judged (quality flags, gate,
    misfit; ``strict`` while lost); a fix whose covariance is not usable fails as
    ``INVALID_COVARIANCE``."""
    world, cov = nav._world(pose, joint)
    pmf = nav.config.online.front_end == "pmf"
    if pmf:  # the grid's half-width
        half_width = GRID_SIGMAS * float(np.sqrt(np.linalg.eigvalsh(cov[:2, :2]).max()))
    else:
        half_width = search_half_width(nav.config, nav.bathymetry, cov[:2, :2])
    laid = laid_poses(nav, k, pose)
    if fix is not None:
        return judge_fix(grown(nav, fix, laid, joint), world, cov, nav.config, half_width,
                         strict=strict, noise=misfit_noise(nav, k, fix.sigma))
    started = _time.perf_counter()
    poses = None if laid is None else to_world(laid, nav.calibration, nav.origin)
    try:
        if pmf:
            made: TerrainFix = posterior_window_fix(nav, k, poses, world, cov)
        else:
            made = make_fix(nav.survey, nav.bathymetry, k, nav.config, world[:2], half_width,
                            poses=poses, first=nav.window_first.get(k), shared=nav.shared_map_variance,
                            error=nav.map_error, drift=nav.fix_drift)
    except MatchingError as exc:
        return failed(k, exc, half_width)
    finally:
        nav.tap_times.append(_time.perf_counter() - started)
    try:
        return judge_fix(grown(nav, made, laid, joint), world, cov, nav.config, half_width,
                         strict=strict or pmf, noise=misfit_noise(nav, k, made.sigma))
    except TangraphError as exc:
        log.warning("%s", exc)
        return failed(k, exc, half_width, FixStatus.INVALID_COVARIANCE)


def position_tide_prior(nav: GraphNavigator, k: int, world, cov) -> tuple[np.ndarray, np.ndarray]:
    """The graph's prediction of ping ``k``'s world position and of the tide, mean ``(3,)`` and
    covariance ``(3, 3)``, from its world prediction ``N(world, cov)``: with the tide the graph
    holds and how it goes with the position, or else the model's tide prior, apart from it."""
    mean, prior = np.append(world[:2], nav.model.tide), np.zeros((3, 3))
    prior[:2, :2], prior[2, 2] = cov[:2, :2], nav.model.tide_std**2
    if nav.tide:  # the graph's belief in the tide, and how it goes with the position
        pose = compose(nav._key_pose, nav._delta[k])
        joint = propagate_joint(nav._key_pose, nav._tide_joint, nav._delta[k], nav._delta_cov[k])
        jac = np.zeros((3, 6))
        jac[:2, :5] = world_jacobian(pose, nav.calibration, nav.origin)[:2]
        jac[2, 5] = 1.0
        mean[2], joint = online_tide.carried(nav, float(nav.survey.time[k] - nav.survey.time[nav._key_of]),
                                             nav._tide_mean, joint)
        tide = jac @ joint @ jac.T
        prior[:2, 2] = prior[2, :2] = tide[:2, 2]
        prior[2, 2] = tide[2, 2]
    return mean, prior


def posterior_window_fix(nav: GraphNavigator, k: int, poses, world, cov) -> WindowFix:
    """The point-mass front end's fix of the window ending at ping ``k``, laid with the world
    ``poses`` of its pings, on the prediction ``N(world, cov)``."""
    first = nav.window_first[k]
    patch = window_patch(nav.survey, k, k - first + 1, min_soundings=nav.config.fixes.tap.min_soundings,
                         poses=poses)
    likelihood, variance, map_variance, slope = window_variances(nav, patch)
    mean, prior = position_tide_prior(nav, k, world, cov)
    return posterior_fix(patch, likelihood, variance, map_variance, slope, mean, prior, tide_factor=nav.tide)


def window_variances(nav: GraphNavigator, patch):
    """The terrain likelihood, the ``patch``'s soundings' variances and map error variances
    ``(N,)`` (None: a perfect map) read where the patch lies (laid from the prediction), not at
    the dead-reckoned footprints (:func:`tangraph.sensors.placed_map_variances`), and the map's
    slope moment."""
    likelihood, variance, counts, error, slope = nav._terrain
    variance = variance[patch.ping, patch.beam]
    if counts is None:
        return likelihood, variance, None, slope
    north, east = (patch.reference_position + patch.offsets).T
    shared, own = placed_map_variances(error, counts[patch.ping, patch.beam], north, east)
    return likelihood, float(nav.model.sounding_std) ** 2 + shared, own, slope


def fix_factor(nav: GraphNavigator, key: int, fix) -> gtsam.NonlinearFactor | None:
    """The factor of an accepted fix when it is not a position fix: the point-mass front
    end's on the position and the tide (None otherwise)."""
    if not (nav.tide and isinstance(fix, WindowFix) and np.all(np.isfinite(fix.joint_mean))):
        return None
    m = nav.model
    return position_tide_factor(key, fix.joint_mean, fix.joint_covariance, nav.origin, m.robust_kernel,
                                m.robust_parameter, online_tide.of_key(nav, key))


def misfit_noise(nav: GraphNavigator, k: int, sigma: float) -> float:
    """The residual std the window of ping ``k`` (its fix's residual std ``sigma``) is held
    against by ``GraphConfig.fixes.misfit_ratio``: the model's ``measurement_std``, or the median
    over the last ``MISFIT_WINDOWS`` windows, this one included, when that is larger (from
    the ``MISFIT_WINDOWS // 3``-th window of the survey on). While the DR's constant errors
    are still unknown every window's patch is laid distorted and fits the map worse than
    the soundings' noise (2-3 m on steep terrain at the start of a survey with a 3.5 deg
    heading bias): that says nothing of the data. A window that fits far worse than the
    ones around it does."""
    if np.isfinite(sigma):
        nav._residuals[k] = float(sigma)
        while len(nav._residuals) > MISFIT_WINDOWS:
            del nav._residuals[next(iter(nav._residuals))]
    if len(nav._residuals) < MISFIT_WINDOWS // 3:  # too few to say what fits
        return nav.model.measurement_std
    return max(nav.model.measurement_std, float(np.median(list(nav._residuals.values()))))


def laid_poses(nav: GraphNavigator, k: int, pose) -> np.ndarray | None:
    """The window's DR-frame poses laid rigidly from the DR-frame pose of ping ``k`` with the
    DR increments (no tear at the keys inside the window); mapped to the world with the
    current calibration they are the calibrated DR's patch."""
    first = nav.window_first.get(k, k - nav.config.window + 1)
    if first < 0:
        return None
    return compose(pose, odometry(nav.survey.dr_pose, k, np.arange(first, k + 1)))


def grown(nav: GraphNavigator, fix: TerrainFix, laid, joint) -> TerrainFix:
    """The covariance the graph gives ``fix`` (:func:`~tangraph.graph.fixes.window_noise`)."""
    check_fix_covariance(fix.covariance, fix_name(fix))
    first, end = int(fix.first), int(fix.index)
    mid = (first + end) // 2
    shape = np.zeros((2, 2))
    if laid is not None and nav.graph.calibrated and laid.shape[0] == end - first + 1:
        jac = world_jacobian(laid[[mid - first, -1]], nav.calibration, nav.origin)
        shape = jac[0, :2, 3:] - jac[1, :2, 3:]
    shared = nav.window_overlap.get(end, nav.config.window / nav.config.spacing)
    overlap = nav.model.fix_inflation * shared
    return window_noise(fix, nav.survey, nav.white, shape, joint[3:, 3:], overlap)


def window_terrain(survey: Survey, bathymetry: BathymetryMap, model: NavigationModel):
    """What the point-mass front end weighs soundings with: the terrain likelihood, every
    sounding's variance ``(K, B)`` at the DR's footprints, the map error's counts and the map's
    error (None: a perfect map; read where a window lies, :func:`window_variances`), and the
    map's slope moment."""
    counts = sounding_map_counts(survey, bathymetry, model)
    error = None if counts is None else map_error(bathymetry, model)
    likelihood = TerrainLikelihood(bathymetry, model.measurement_std)
    return likelihood, sounding_variances(survey, bathymetry, model), counts, error, slope_moment(bathymetry)


def tide_step(nav: GraphNavigator, k: int) -> None:
    """After the window ending at ``k``: when the point-mass front end's windows have found
    the same depth fault (within ``TIDE_STEP_AGREE``) over ``TIDE_STEP_PINGS`` pings in a row,
    it is the held tide that is wrong (a step of the water level or the datum, or a start on a bad
    block), not their depths: the graph holds a new tide from here, its prior the old
    estimate moved by their offset with the model's tide std."""
    outcome = nav._last_outcome if nav._last_outcome and nav._last_outcome.record.index == k else None
    fix = None if outcome is None else outcome.fix
    offset = getattr(fix, "depth_offset", float("nan"))
    if not np.isfinite(offset):
        if outcome is not None and outcome.record.status is not FixStatus.MATCH_FAILED:
            nav._faults = []
        return
    nav._faults.append((k, float(offset)))
    offsets = np.array([o for _, o in nav._faults])
    if k - nav._faults[0][0] < TIDE_STEP_PINGS or np.ptp(offsets) > TIDE_STEP_AGREE:
        if np.ptp(offsets) > TIDE_STEP_AGREE:  # not one offset: faults of their own
            nav._faults = nav._faults[-1:]
        return
    online_tide.new_tide(nav, k, nav._tide_mean + float(np.median(offsets)))
    log.info("graph: the tide stepped at ping %d: windows over %d pings %.2f m off the held tide",
             k, k - nav._faults[0][0] + 1, float(np.median(offsets)))
    nav._faults = []


def grow_window(nav: GraphNavigator, k: int) -> None:
    """The point-mass front end's next window: the pings after ``k``, or, when the window
    ending at ``k`` was multimodal or uninformative and ``GraphConfig.fixes.n_pings`` allows, the
    same window grown by the next ``front_end_pings`` pings (its pings are not lost: one
    window's soundings together may settle what a few could not)."""
    record = nav.fixes[-1] if nav.fixes and nav.fixes[-1].index == k else None
    held = record is not None and record.status in (FixStatus.MULTIMODAL, FixStatus.UNINFORMATIVE)
    if not (held and k + nav.config.spacing - nav._window_start + 1 <= nav.config.fixes.n_pings):
        nav._window_start = k + 1
