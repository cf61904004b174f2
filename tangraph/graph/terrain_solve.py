"""The smoother's last solve on every sounding: terrain factors per ping instead of the fixes,
and optionally the map's error estimated with the track.

With ``GraphConfig.batch.smoother_terrain = "soundings"`` the fixes are replaced by every sounding,
each a terrain factor on a key pose at its ping (:mod:`tangraph.graph.terrain_factors`):
Gauss-Newton from the fixes' solution, with a tide variable, re-linearised at every iteration;
the soundings judged as innovations of the fixes' solution, one by one and ping by ping, again
after each converged solve; their variances grown by the scatter of the solution's own windows
(an a posteriori variance factor) while it moves. A ping that windows refused as multimodal
cover, and no accepted one, is left to the fixes (:func:`placed_pings`): the search found
several places around the track there, and a linearised sounding would claim the slope's
information about a place the track may not be.

With ``"field"`` the map's error is a field of unknowns solved with the track
(:mod:`tangraph.graph.field_solve`) instead of a variance each sounding is widened by: the
soundings are judged against the map's stated error (each sounding's own, and an offset a
ping's soundings share), the soundings' noise grown by its a posteriori variance factor and the
field's std by the factor each patch of it shows, and the solution carries the refined map.
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time

import gtsam
import numpy as np

from tangraph.eval.map_field import map_error_field
from tangraph.eval.windows import window_scores
from tangraph.fix_records import FixStatus
from tangraph.geometry import wrap_near
from tangraph.graph import batch, field_solve, terrain_factors
from tangraph.graph.batch import SmootherSolution
from tangraph.graph.calibration import CALIBRATION, MAP_OFFSET, TIDE, joint_in_frame, to_world
from tangraph.graph.config import GraphConfig
from tangraph.graph.keyposes import PoseGraph, increments
from tangraph.graph.online import GraphNavigator
from tangraph.maps.grid import BathymetryMap

__all__ = ["SOUNDING_GATE", "WINDOW", "placed_pings", "terrain_solve"]

log = logging.getLogger(__name__)


#: A sounding whose standardised residual is beyond this is left out of the terrain solve
#: (two-sided 0.999 of a normal): where the map or the sounding is wrong.
SOUNDING_GATE = 3.29
_GATE_ROUNDS = 5  # re-gating rounds of the terrain solve at most
#: Windows of track (m) whose mean residuals test the soundings' variances after a solve, as
#: check lines test a map (:func:`tangraph.eval.windows.window_scores`)
WINDOW = 50.0
_FACTOR_ROUNDS = 4  # solves at most while the variance factor the windows show still moves


def terrain_solve(nav: GraphNavigator, start_kept: bool, solution: SmootherSolution, records,
                  config: GraphConfig) -> tuple[SmootherSolution, dict, BathymetryMap | None]:  # fmt: skip
    """The batch solve with every sounding as a terrain factor instead of the fixes
    (:mod:`tangraph.graph.terrain_factors`), from ``solution``, on a key pose at every ping
    (:func:`_ping_graph`: the white DR noise between pings is then the odometry's, correlations
    and all): Gauss-Newton on the odometry, the priors (the start's if the robust solve kept
    it), the tide's and the soundings, the soundings re-gated at each converged solve; with
    ``config.batch.smoother_terrain = "field"`` and a map that states its error, the map's error
    solved with them (:func:`_field_solve`). The pings that windows of ``records`` refused as
    multimodal cover, and no accepted one, are not terrain factors (:func:`placed_pings`).
    Returns the solution (its keys every ping), what it used (``soundings``, all of them;
    ``soundings_used``; ``pings_left_out``; the tide and the variance factors) and the refined
    map (None but with ``"field"``)."""
    placed = placed_pings(nav, records)
    if not placed.all():
        log.info("terrain solve: %d of %d pings lie where windows found several places: left to the fixes",
                 int((~placed).sum()), placed.size)
    solved, used, refined = _solve(nav, start_kept, solution, placed, config)
    used.update(soundings=int(np.isfinite(nav.survey.beam_depth).sum()), pings_left_out=int((~placed).sum()))
    return solved, used, refined


def _solve(nav: GraphNavigator, start_kept: bool, solution: SmootherSolution, placed: np.ndarray,
           config: GraphConfig) -> tuple[SmootherSolution, dict, BathymetryMap | None]:  # fmt: skip
    """:func:`terrain_solve` with the soundings of the pings ``placed``."""
    started = _time.perf_counter()
    fixes_solution = solution
    graph = _ping_graph(nav)
    world, world_cov = batch.dense_track(nav.survey, nav.white, solution, nav.origin)
    # the map's error read where the fixes' solution puts the soundings, not the DR
    terrain = terrain_factors.ping_terrain(nav.survey, nav.bathymetry, nav.model, graph.keys, nav.white,
                                           nav.origin, graph.calibrated, poses=world)
    terrain = dataclasses.replace(terrain, depth=np.where(placed[:, None], terrain.depth, np.nan))
    if not placed.any():
        return _nothing_fits(fixes_solution, terrain, "every window found several places")
    factors = graph.with_fixes([], start=start_kept).factor_graph()
    # the soundings are judged as innovations of the fixes' solution, whose uncertainty this is
    prior = np.where(np.isfinite(world_cov[:, :2, :2]), world_cov[:, :2, :2], 0.0)
    initial = batch.frame_poses(world, solution.calibration, nav.origin) if graph.calibrated else world
    solution = dataclasses.replace(solution, keys=np.asarray(graph.keys), pose=initial)
    values = graph.values(solution.pose, solution.calibration)
    if terrain.estimates_tide:  # started at the soundings' median residual, gated around it
        factors.add(gtsam.PriorFactorVector(TIDE, np.array([terrain.tide]),
                                            gtsam.noiseModel.Isotropic.Sigma(1, terrain.tide_std)))
        residual = terrain_factors.terrain_residuals(terrain, nav.bathymetry, solution.pose,
                                                     solution.calibration, 0.0)
        finite = residual[np.isfinite(residual)]
        start = float(np.median(finite)) if finite.size else terrain.tide
        values.insert(TIDE, np.array([start]))
    state = _unpack(values, terrain, solution.pose)
    if config.batch.smoother_terrain == "field" and nav.map_error is not None:
        if nav.model.map_offset_std > 0 and nav.model.map_offset_length == 0:  # one for the survey
            terrain = dataclasses.replace(terrain, map_offset_std=float(nav.model.map_offset_std))
            factors.add(gtsam.PriorFactorVector(MAP_OFFSET, np.zeros(2),
                                                gtsam.noiseModel.Isotropic.Sigma(2, terrain.map_offset_std)))
            values.insert(MAP_OFFSET, np.zeros(2))
        return _field_solve(nav, factors, values, terrain, prior, solution.pose, fixes_solution, config,
                            started)
    used = terrain_factors.gate(terrain, nav.bathymetry, *state, SOUNDING_GATE, prior)
    if not used.any():
        return _nothing_fits(fixes_solution, terrain)
    base, factor, iterations = terrain, 1.0, 0
    for _ in range(_FACTOR_ROUNDS):
        values, used, ordering, n = _gated_solve(factors, values, terrain, nav.bathymetry, used, config,
                                                 solution.pose, prior)
        iterations += n
        state = _unpack(values, terrain, solution.pose)
        world = to_world(state[0], state[1], nav.origin) if graph.calibrated else state[0]
        scores = window_scores(nav.survey, nav.bathymetry, nav.model, window=WINDOW, poses=world, used=used)
        found = max(1.0, float(np.sqrt(np.mean(scores**2)))) if scores.size else 1.0
        if abs(found - factor) <= 0.05 * factor:
            break
        factor = found
        terrain = dataclasses.replace(base, variance=base.variance * factor**2)
        log.info("terrain solve: the soundings' windows scatter %.2f times what the model says: "
                 "their variances grown by that", factor)
    solved = _time.perf_counter()
    pose, calibration, tide = state
    keys = np.asarray(graph.keys, np.int64)
    cov, calib_cov = np.full((keys.size, 5, 5), np.nan), np.zeros((2, 2))
    if config.batch.smoother_covariance == "all":
        extra = terrain_factors.linear_factors(terrain, nav.bathymetry, pose, calibration, tide, used)
        cov, calib_cov = batch.marginals(factors, values, keys, ordering, graph.calibrated, extra)
        cov = joint_in_frame(pose[:, 2], cov)
    error = factors.error(values) + terrain_factors.terrain_cost(terrain, nav.bathymetry, *state, used)
    timings = {"solve": solved - started, "marginals": _time.perf_counter() - solved}
    used_info = {"soundings": int(np.isfinite(terrain.depth).sum()), "soundings_used": int(used.sum()),
                 "tide": float(tide), "variance_factor": factor}
    return SmootherSolution(keys, pose, cov, calibration if graph.calibrated else np.zeros(2), calib_cov,
                            iterations, float(error), timings), used_info, None


def placed_pings(nav: GraphNavigator, records) -> np.ndarray:
    """The pings ``(n,)`` the terrain solve may linearise: every ping of the window of a fix of
    ``records`` the solve accepted, and every ping that no window refused as multimodal covers
    (``FixStatus.MULTIMODAL``: several places fit, and ``GraphConfig.fixes.accept_multimodal =
    False`` refuses such fixes). Where the windows' search found several places around the
    track, a Gauss-Newton solve from the fixes' solution stays in whichever dip of the map it
    starts in and takes the slope there for information: on a flat lake shelf where 90 of 119
    windows were multimodal, 20 000 soundings linearised along a dead-reckoned track 24 m off
    did not move it and gave it a std of 2 m. A window with one place, or none that stands out
    (a plane tells the position across its slope and nothing along it, its best match anywhere
    along the slope, on the search's edge too), leaves its pings to the linearisation, which
    weighs what their slopes tell."""
    accepted = np.zeros(nav.survey.n_pings, bool)
    ambiguous = np.zeros(nav.survey.n_pings, bool)
    for record in records:
        window = slice(max(int(nav.window_first[record.index]), 0), record.index + 1)
        if record.accepted:
            accepted[window] = True
        elif record.status is FixStatus.MULTIMODAL:
            ambiguous[window] = True
    return accepted | ~ambiguous


def _nothing_fits(fixes_solution: SmootherSolution, terrain,
                  why: str = f"no sounding fits the map within {SOUNDING_GATE:.2f} sigma"
                  ) -> tuple[SmootherSolution, dict, None]:  # fmt: skip
    """The fixes' solution when no sounding passes the gate, or none may be linearised (nothing
    would tie ``c`` and the tide to the poses, and METIS fails on that)."""
    log.warning("terrain solve: %s; the fixes' solution is kept", why)
    return fixes_solution, {"soundings": int(np.isfinite(terrain.depth).sum()), "soundings_used": 0,
                            "tide": float(terrain.tide), "variance_factor": 1.0}, None


def _field_solve(nav: GraphNavigator, factors, values, terrain, prior, reference, fixes_solution,
                 config: GraphConfig, started: float) -> tuple[SmootherSolution, dict, BathymetryMap | None]:
    """The terrain solve with the map's error (and its horizontal offset, ``map_offset_length >
    0``) as fields of unknowns (:mod:`.field_solve`) over the fixes' solution's footprints. A
    sounding's variance is its noise and shared nugget; the gate judges the soundings against
    the map's stated error (its std under each, its mean under a ping as an offset they share).
    Each converged solve grows the soundings' noise and each patch of the field by their a
    posteriori variance factors (never below the model's). Returns the solution, its use, the map."""
    bathymetry, error = nav.bathymetry, nav.map_error
    assert error is not None  # the caller's condition
    north, east = terrain_factors.footprints(terrain, bathymetry, *_unpack(values, terrain, reference)[:2])
    seen = np.isfinite(terrain.depth) & np.isfinite(bathymetry.depth_at(north, east))
    if not seen.any():
        return _nothing_fits(fixes_solution, terrain)
    placed, noise = (nav.model.map_offset_std, nav.model.map_offset_length), nav.model.sounding_std**2
    hold = field_solve.FieldSoundings.at(map_error_field(north[seen], east[seen], error, offset=placed),
                                         north, east, seen)
    s2 = np.where(seen, error.std_at(north, east) ** 2, np.nan)
    s2, counts = np.where(seen & ~np.isfinite(s2), error.typical_std**2, s2), seen.sum(axis=1)

    def unpack(v) -> tuple[np.ndarray, np.ndarray, float, np.ndarray | None]:
        return *_unpack(v, terrain, reference), _map_offset(v, terrain)

    def judged(v, noise_factor: float, ratio) -> np.ndarray:
        grown = s2 * ratio
        judging = dataclasses.replace(terrain, variance=np.where(seen, noise * noise_factor**2 + grown,
                                                                 np.nan))
        shared = np.divide(np.nansum(np.where(seen, grown, 0.0), axis=1), counts, out=np.zeros(counts.size),
                           where=counts > 0)
        p, c, t, o = unpack(v)  # key poses, calibration, tide, map offset
        return terrain_factors.gate(judging, bathymetry, p, c, t, SOUNDING_GATE, prior, shared, o)

    used = judged(values, 1.0, 1.0)
    if not used.any():
        return _nothing_fits(fixes_solution, terrain)
    keys, patch = np.asarray(terrain.keys, np.int64), field_solve.patches(hold.field)
    u, iterations, noise_factor, field_factor, scaled = None, 0, 1.0, np.ones(hold.field.n_nodes), hold
    for rounds in range(1, _FACTOR_ROUNDS + 1):
        solving = dataclasses.replace(terrain, variance=noise * noise_factor**2 + scaled.nugget)
        for attempt in range(_GATE_ROUNDS):
            solved = field_solve.solve(factors, values, solving, bathymetry, scaled, used, unpack, u=u,
                                       max_iterations=config.batch.max_iterations)
            values, u, iterations = solved.values, solved.u, iterations + solved.iterations
            regated = judged(values, noise_factor, hold.variance_ratio(field_factor))
            # ``used`` stays the last solve's: its system holds those soundings and no others
            if np.array_equal(regated, used) or not regated.any() or attempt == _GATE_ROUNDS - 1:
                break
            used = regated
        cov, calib_cov, inverse = field_solve.marginals(solved, keys, terrain.calibrated)
        found = field_solve.variance_components(solved, solving, bathymetry, scaled, used, unpack, inverse)
        new_noise = max(1.0, noise_factor * np.sqrt(found["noise"]))
        new_field = field_solve.patch_factors(found, field_factor, patch)
        if rounds == _FACTOR_ROUNDS or (abs(new_noise - noise_factor) <= 0.05 * noise_factor
                                        and np.all(np.abs(new_field - field_factor) <= 0.05 * field_factor)):
            break
        log.info("terrain solve: the soundings scatter %.2f and the map's error %.2f (in patches up to "
                 "%.2f) times what the model says: grown by that", new_noise, np.median(new_field),
                 new_field.max())
        noise_factor, field_factor = new_noise, new_field
        scaled = hold.scaled(field_factor)
    done = _time.perf_counter()
    pose, calibration, tide, shift = unpack(values)
    cov = joint_in_frame(pose[:, 2], cov)
    found_error = field_solve.scaled_error(error, hold.field, field_factor)
    refined = field_solve.refined_map(found_error, scaled.field, solved, inverse)
    if config.batch.smoother_covariance != "all":
        cov, calib_cov = np.full_like(cov, np.nan), np.zeros((2, 2))
    assert u is not None  # solved at least once
    offset = scaled.offset(u)
    cost = factors.error(values) + 0.5 * float(u @ (scaled.field.precision @ u)) + \
        terrain_factors.terrain_cost(solving, bathymetry, pose, calibration, tide, used, offset, shift)
    info = {"soundings": int(np.isfinite(terrain.depth).sum()), "soundings_used": int(used.sum()),
            "tide": float(tide), "variance_factor": float(noise_factor),
            "field_factor": float(np.median(field_factor)), "field_factor_max": float(field_factor.max()),
            "field_nodes": int(scaled.field.n_nodes), "field_spacing": float(scaled.field.spacing),
            "field_rms": float(np.sqrt(np.mean(offset[used] ** 2))),
            **field_solve.offset_estimate(solved, inverse, terrain.estimates_offset)}
    timings = {"solve": done - started, "marginals": _time.perf_counter() - done}
    return SmootherSolution(keys, pose, cov, calibration if terrain.calibrated else np.zeros(2), calib_cov,
                            iterations, float(cost), timings), info, refined


def _map_offset(values, terrain) -> np.ndarray | None:
    """The map's horizontal offset in ``values`` (None when it is not a variable)."""
    return np.asarray(values.atVector(MAP_OFFSET), float) if terrain.estimates_offset else None


def _gated_solve(factors, values, terrain, bathymetry, used, config: GraphConfig, reference, prior):
    """Gauss-Newton with the soundings ``used``, re-gated at each converged solve (as innovations
    against ``prior``) until the gate keeps the same soundings (at most ``_GATE_ROUNDS``).
    Returns the values, the soundings used, the last ordering and the iterations."""
    iterations = 0
    for _ in range(_GATE_ROUNDS):
        # METIS on the linear system with the terrain factors (their links to c and the tide)
        linear = factors.linearize(values)
        state = _unpack(values, terrain, reference)
        for factor in terrain_factors.linear_factors(terrain, bathymetry, *state, used):
            linear.push_back(factor)
        ordering = batch.shared_last(gtsam.Ordering.MetisGaussianFactorGraph(linear))
        values, n = batch.gauss_newton(factors, values, ordering, config.batch.max_iterations,
                                  **_terrain_terms(terrain, bathymetry, used, reference))
        iterations += n
        state = _unpack(values, terrain, reference)
        regated = terrain_factors.gate(terrain, bathymetry, *state, SOUNDING_GATE, prior)
        if np.array_equal(regated, used) or not regated.any():
            break
        used = regated
    return values, used, ordering, iterations


def _terrain_terms(terrain, bathymetry, used, reference) -> dict:
    """The soundings ``used`` as :func:`gauss_newton`'s extra cost and linear factors."""

    def cost(values) -> float:
        return terrain_factors.terrain_cost(terrain, bathymetry, *_unpack(values, terrain, reference), used)

    def linear(values) -> list:
        return terrain_factors.linear_factors(terrain, bathymetry, *_unpack(values, terrain, reference), used)

    return {"extra_cost": cost, "extra_factors": linear}


def _ping_graph(nav: GraphNavigator) -> PoseGraph:
    """The forward pass's graph with a key pose at every ping: its start (the DR's first pose,
    the model's uncertainty), its calibration prior, and the DR increments between consecutive
    pings as odometry; no fix, no break. The odometry's noise floors (added to every increment)
    are shrunk so that over the forward pass's key interval they add up to the same."""
    survey, model = nav.survey, nav.model
    shrink = np.sqrt(max(len(nav.graph.keys) - 1, 1) / max(survey.n_pings - 1, 1))
    graph = PoseGraph(nav.graph.calibration_std, nav.graph.calibration_mean, nav.origin, model.robust_kernel,
                      model.robust_parameter, model.odometry_min_std * shrink,
                      model.odometry_min_heading_std * shrink)
    for k in range(survey.n_pings):
        graph.add_pose(k, survey.time[k], survey.dr_pose[k])
    graph.add_start(0, survey.dr_pose[0], model.initial_position_std,
                    max(model.heading_noise, model.odometry_min_heading_std))  # as the forward pass's
    ping = np.arange(survey.n_pings)
    delta, cov = increments(nav.white, survey.time, survey.dr_pose, ping[:-1], ping[1:])
    for k in range(survey.n_pings - 1):
        graph.add_odometry(k, k + 1, delta[k], cov[k])
    return graph


def _unpack(values, terrain, reference) -> tuple[np.ndarray, np.ndarray, float]:
    """Key poses (headings unwrapped near ``reference``), calibration and tide of ``values``."""
    pose = np.array(gtsam.utilities.extractPose2(values), float)
    pose[:, 2] = wrap_near(pose[:, 2], reference[:, 2])
    calibration = np.asarray(values.atVector(CALIBRATION), float) if terrain.calibrated else np.zeros(2)
    tide = float(values.atVector(TIDE)[0]) if terrain.estimates_tide else terrain.tide
    return pose, calibration, tide
