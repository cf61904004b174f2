"""Batch smoother: every key pose and factor of a recorded survey solved at once.

The factors come from a forward pass of :class:`~tangraph.graph.GraphNavigator` (its fixes were
searched and gated online). Levenberg-Marquardt (or Gauss-Newton, dogleg) solves the whole
graph with METIS ordering: the default COLAMD ordering makes an elimination tree as deep as the
chain, which overflows the stack on chains of about 10^5 poses. The marginal covariance of every
key pose comes from one multifrontal elimination of the linearised graph, also ordered by METIS
(``gtsam.Marginals`` cannot be given an ordering from Python and crashes on such chains).

With ``GraphConfig.smoother_terrain = "soundings"`` a last solve replaces the fixes by every
sounding, each a terrain factor on a key pose at its ping (:mod:`tangraph.graph.terrain_factors`):
Gauss-Newton from the fixes' solution, with a tide variable, re-linearised at every iteration;
the soundings judged as innovations of the fixes' solution, one by one and ping by ping, again
after each converged solve; their variances grown by the scatter of the solution's own windows
(an a posteriori variance factor) while it moves.

The ping-rate track is recovered from the key poses and the DR: a ping between keys ``a`` and
``b`` is predicted forward from ``a`` and backward from ``b`` by the DR increments, and the two
are blended linearly in time (the correction is distributed between the neighbouring keys); its
covariance is the same blend of the two propagated covariances.
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time

import gtsam
import numpy as np

from tangraph.errors import TangraphError
from tangraph.eval.map_check import window_scores
from tangraph.graph import terrain_factors
from tangraph.graph.calibration import CALIBRATION, TIDE, joint_in_frame, to_world, world_covariance
from tangraph.graph.config import GraphConfig
from tangraph.graph.factors import compose, inverse_increment_covariance, propagate_joint
from tangraph.graph.fixes import FixRecord, FixStatus, failed, judge_fix, make_fix, search_half_width
from tangraph.graph.keyposes import PoseGraph, increments
from tangraph.graph.online import GraphNavigator, _translate, _wrap, calibration_summary
from tangraph.graph.robust import gnc
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import MatchingError
from tangraph.sensors import DeadReckoningModel, NavigationModel, odometry, rotation_matrix
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["SmootherSolution", "dense_track", "smooth_pose_graph", "smooth_survey"]

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, eq=False)
class SmootherSolution:
    """A batch solve: key poses ``(n, 3)`` (in the DR frame when the graph is calibrated), their
    joint covariances with the calibration ``(n, 5, 5)`` (pose in world coordinates of its frame,
    then ``(k, b)``; NaN if not computed), the ``calibration (2,)`` and its covariance ``(2, 2)``
    (zeros when the graph has no calibration variable)."""

    keys: np.ndarray
    pose: np.ndarray
    covariance: np.ndarray
    calibration: np.ndarray
    calibration_cov: np.ndarray
    iterations: int
    error: float
    timings: dict


def _optimizer(graph, values, config: GraphConfig, ordering):
    if config.optimizer == "lm":
        params = gtsam.LevenbergMarquardtParams()
        cls = gtsam.LevenbergMarquardtOptimizer
    elif config.optimizer == "gn":
        params = gtsam.GaussNewtonParams()
        cls = gtsam.GaussNewtonOptimizer
    else:
        params = gtsam.DoglegParams()
        cls = gtsam.DoglegOptimizer
    params.setOrdering(ordering)  # METIS, computed once for every iteration
    params.setMaxIterations(config.max_iterations)
    return cls(graph, values, params)


def smooth_pose_graph(graph: PoseGraph, config: GraphConfig | None = None, *,
                      initial=None, calibration=None) -> SmootherSolution:
    """Solve a whole :class:`~tangraph.graph.keyposes.PoseGraph` (METIS ordering).

    Parameters
    ----------
    graph : PoseGraph
    config : GraphConfig, optional
        ``optimizer``, ``max_iterations`` and ``smoother_covariance`` are used.
    initial : array_like (n_keys, 3), optional
        Initial key poses (default: those stored in the graph).
    calibration : array_like (2,), optional
        Initial calibration (default: its prior mean).

    Raises
    ------
    TangraphError
        Key poses that nothing constrains (a gap with no odometry), named by ping.

    Examples
    --------
    >>> import numpy as np
    >>> graph = PoseGraph()
    >>> graph.add_pose(0, 0.0, [0.0, 0.0, 0.0])
    >>> graph.add_pose(10, 10.0, [10.0, 0.0, 0.0])
    >>> _ = graph.add_pose_prior(0, [0.0, 0.0, 0.0], np.diag([1.0, 1.0, 0.01]))
    >>> _ = graph.add_odometry(0, 10, [10.0, 0.0, 0.0], np.diag([0.1, 0.1, 1e-4]))
    >>> _ = graph.add_position_fix(10, [12.0, 0.0], np.eye(2))
    >>> solution = smooth_pose_graph(graph)
    >>> solution.pose[:, 0].round(2).tolist()
    [0.95, 11.05]
    """
    config = config or GraphConfig()
    graph.check_determined()
    factors, values = graph.factor_graph(), graph.values(initial, calibration)
    started = _time.perf_counter()
    try:
        ordering = _ordering(factors, graph.calibrated)
        if graph.calibrated:
            result, iterations = _gauss_newton(factors, values, ordering, config.max_iterations)
        else:
            optimizer = _optimizer(factors, values, config, ordering)
            result = optimizer.optimize()
            iterations = int(optimizer.iterations())
    except (RuntimeError, IndexError) as exc:  # GTSAM's indeterminant system; METIS on odd graphs
        raise _translate(exc, graph) from None
    solved = _time.perf_counter()
    keys = np.asarray(graph.keys, np.int64)
    pose = np.array(gtsam.utilities.extractPose2(result), float)  # in key order: the pings ascending
    if initial is None:
        initial = np.asarray(graph.initial)
    pose[:, 2] = np.asarray(initial)[:, 2] + _wrap(pose[:, 2] - np.asarray(initial)[:, 2])
    calib = np.zeros(2)
    if graph.calibrated:
        calib = np.asarray(result.atVector(CALIBRATION), float)
    cov = np.full((keys.size, 5, 5), np.nan)
    calib_cov = np.zeros((2, 2))
    if config.smoother_covariance == "all":
        cov, calib_cov = _marginals(factors, result, keys, ordering, graph.calibrated)
        cov = joint_in_frame(pose[:, 2], cov)
    done = _time.perf_counter()
    timings = {"solve": solved - started, "marginals": done - solved}
    return SmootherSolution(keys, pose, cov, calib, calib_cov, iterations,
                            float(factors.error(result)), timings)


def _gauss_newton(factors, values, ordering, max_iterations: int, tolerance: float = 1e-6, *,
                  extra_cost=None, extra_factors=None):
    """Gauss-Newton with step halving, driven from here: GTSAM's optimizer objects take about ten
    times longer per iteration than linearise + solve + retract on a graph with Python factors
    (measured: 2.8 s against 0.25 s on a 20 000-pose chain). ``extra_cost(values)`` and
    ``extra_factors(values)`` (linear factors, re-linearised at every iteration) add terms that
    are not in ``factors`` (the terrain solve's soundings)."""

    def cost(v) -> float:
        return factors.error(v) + (extra_cost(v) if extra_cost is not None else 0.0)

    error = cost(values)
    for iteration in range(1, max_iterations + 1):
        linear = factors.linearize(values)
        for factor in extra_factors(values) if extra_factors is not None else ():
            linear.push_back(factor)
        delta = linear.optimize(ordering)
        step = 1.0
        while True:
            trial = values.retract(delta if step == 1.0 else delta.scale(step))
            new = cost(trial)
            if new <= error or step < 1e-3:
                break
            step *= 0.5
        if new > error:  # no step lowers the error: converged as far as it goes
            return values, iteration
        converged = error - new <= tolerance * max(error, 1e-12)
        values, error = trial, new
        if converged:
            return values, iteration
    return values, max_iterations


def _ordering(factors, calibrated: bool):
    """METIS ordering, with the calibration (joined to every fix) and the tide (joined to every
    terrain factor) moved to the end: eliminated early they would join all the poses they touch
    into one dense clique."""
    return _shared_last(gtsam.Ordering.MetisNonlinearFactorGraph(factors))


def _shared_last(metis):
    """A METIS ordering with the calibration and the tide, where present, moved to the end."""
    shared = [key for key in (CALIBRATION, TIDE) if key in {metis.at(i) for i in range(metis.size())}]
    if not shared:
        return metis
    ordering = gtsam.Ordering()
    for i in range(metis.size()):
        key = metis.at(i)
        if key not in shared:
            ordering.push_back(key)
    for key in shared:
        ordering.push_back(key)
    return ordering


def _marginals(factors, result, keys, ordering, calibrated: bool, extra=()) -> tuple[np.ndarray, np.ndarray]:
    """Joint covariances (tangent, then ``c``) of every key pose with the calibration, and that of
    the calibration, from one METIS-ordered elimination of the linearised graph (and the linear
    factors ``extra``, the terrain's).

    The pose blocks are the tree's marginals; the cross-covariance of a pose with ``c`` is
    ``E Sigma_cc``, ``E`` the sensitivity of the pose's conditional mean to ``c``, which two more
    solves of the linear system with ``c`` pinned to a unit step give."""
    linear = factors.linearize(result)
    for factor in extra:
        linear.push_back(factor)
    try:
        tree = linear.eliminateMultifrontal(ordering)
    except RuntimeError as exc:
        raise TangraphError(f"marginal covariances failed: {str(exc).strip().splitlines()[0]}") from None
    out = np.zeros((keys.size, 5, 5))
    out[:, :3, :3] = np.array([tree.marginalCovariance(int(k)) for k in keys])
    if not calibrated:
        return out, np.zeros((2, 2))
    calib_cov = np.asarray(tree.marginalCovariance(CALIBRATION), float)
    base = _pinned_solution(linear, ordering, keys, np.zeros(2))
    sensitivity = np.stack([_pinned_solution(linear, ordering, keys, e) - base for e in np.eye(2)], axis=-1)
    cross = sensitivity @ calib_cov
    out[:, :3, 3:] = cross
    out[:, 3:, :3] = np.swapaxes(cross, 1, 2)
    out[:, 3:, 3:] = calib_cov
    return out, calib_cov


def _pinned_solution(linear, ordering, keys, step) -> np.ndarray:
    """The linear system's solution for every key pose ``(n, 3)`` with ``c``'s step pinned."""
    pinned = linear.clone()
    weight = 1e8
    pinned.add(gtsam.JacobianFactor(CALIBRATION, weight * np.eye(2), weight * np.asarray(step, float),
                                    gtsam.noiseModel.Unit.Create(2)))
    delta = pinned.optimize(ordering)
    return np.array([delta.at(int(k)) for k in keys])


def dense_track(survey: Survey, white: DeadReckoningModel, solution: SmootherSolution, origin
                ) -> tuple[np.ndarray, np.ndarray]:
    """World poses ``(K, 3)`` and covariances ``(K, 3, 3)`` at every ping from a smoothed solution.

    Between keys ``a < b`` a ping is predicted forward from ``a`` and backward from ``b`` with the
    DR increments (noise of the white DR model ``white``); DR-frame poses and joint covariances
    with the calibration are blended with weight ``(t - t_a) / (t_b - t_a)`` and mapped to the
    world with the smoothed calibration.
    """
    keys = np.asarray(solution.keys, np.int64)
    key_pose, key_cov = solution.pose, np.where(np.isfinite(solution.covariance), solution.covariance, 0.0)
    t, dr = survey.time, survey.dr_pose
    ping = np.arange(survey.n_pings)
    n_key = np.searchsorted(keys, ping, side="right") - 1
    a = keys[n_key]
    b = keys[np.minimum(n_key + 1, keys.size - 1)]
    b = np.where(a == ping, ping, b)
    ia, ib = n_key, np.searchsorted(keys, b)
    fwd, fwd_q = increments(white, t, dr, a, ping)
    back_q = increments(white, t, dr, ping, b)[1]
    back = odometry(dr, b, ping)
    back_q = inverse_increment_covariance(back, back_q)
    pose_f, pose_b = compose(key_pose[ia], fwd), compose(key_pose[ib], back)
    cov_f = propagate_joint(key_pose[ia], key_cov[ia], fwd, fwd_q)
    cov_b = propagate_joint(key_pose[ib], key_cov[ib], back, back_q)
    span = t[b] - t[a]
    w = np.divide(t - t[a], span, out=np.zeros_like(t), where=span > 0)
    pose = pose_f + w[:, None] * np.column_stack([pose_b[:, :2] - pose_f[:, :2],
                                                  _wrap(pose_b[:, 2] - pose_f[:, 2])])
    joint = (1 - w)[:, None, None] * cov_f + w[:, None, None] * cov_b
    return (to_world(pose, solution.calibration, origin),
            world_covariance(pose, joint, solution.calibration, origin))


def _rematch(nav: GraphNavigator, pose, cov, solution: SmootherSolution) -> list[FixRecord]:
    """Fixes re-made around the smoothed world track ``pose``, searched and gated with the
    smoothed covariances ``cov``: one record per TAP window."""
    config = nav.config
    records = []
    joint = np.zeros((5, 5))
    joint[3:, 3:] = solution.calibration_cov
    nav.calibration = solution.calibration
    for end in nav.fix_ends:
        end = int(end)
        half_width = search_half_width(config, nav.bathymetry, cov[end, :2, :2])
        window = slice(nav.window_first[end], end + 1)
        try:
            fix = make_fix(nav.survey, nav.bathymetry, end, config, pose[end, :2], half_width,
                           poses=pose[window], first=window.start, shared=nav.shared_map_variance,
                           error=nav.map_error)
            laid = None if window.start < 0 else _frame_poses(pose[window], solution.calibration, nav.origin)
            # laid with the smoothed calibration: the model's noise is the misfit reference
            outcome = judge_fix(nav._grown(fix, laid, joint), pose[end], cov[end], config, half_width,
                                noise=nav.model.measurement_std)
        except MatchingError as exc:
            outcome = failed(end, exc, half_width)
        except TangraphError as exc:
            outcome = failed(end, exc, half_width, FixStatus.INVALID_COVARIANCE)
        records.append(outcome.record)
    return records


def _moved(before: list[FixRecord], after: list[FixRecord], tolerance: float) -> bool:
    """Whether the set of fixes used changed, or one of them moved by more than ``tolerance`` m."""
    old = {r.index: r for r in before}
    for record in after:
        previous = old.get(record.index)
        if previous is None or previous.accepted != record.accepted:
            return True
        if record.accepted and np.hypot(previous.north - record.north,
                                        previous.east - record.east) > tolerance:
            return True
    return False


#: Outcomes whose fix the robust solve weighs: used online, refused by the online gate (which
#: may have been wrong), held for confirmation (still held, or never confirmed), a relocalisation
#: candidate, given up, or left when its key pose left iSAM2's window online, or found an outlier
#: by an earlier robust solve (records passed in again are weighed afresh).
_CANDIDATES = (FixStatus.ACCEPTED, FixStatus.GATE, FixStatus.HELD, FixStatus.UNCONFIRMED, FixStatus.CANDIDATE,
               FixStatus.GIVEN_UP, FixStatus.LEFT_WINDOW, FixStatus.OUTLIER)


def _solve(graph: PoseGraph, records: list[FixRecord], config: GraphConfig, initial, calibration
           ) -> tuple[SmootherSolution, list[FixRecord], bool]:
    """The batch solve of ``graph`` with the fixes of ``records``: with ``robust_solve="gnc"``
    the candidates' inliers (and whether the start prior is one) by :func:`~tangraph.graph.robust.gnc`,
    then the solve with the inliers only; otherwise the accepted fixes. Returns the solution,
    the records with their final status and whether the start prior was kept."""
    if config.robust_solve != "gnc":
        fixes = [(r.index, r.position, r.covariance) for r in records if r.accepted]
        return smooth_pose_graph(graph.with_fixes(fixes), config, initial=initial,
                                 calibration=calibration), records, True
    chosen = [n for n, r in enumerate(records) if r.status in _CANDIDATES]
    fixes = [(records[n].index, records[n].position, records[n].covariance) for n in chosen]
    inlier, keep_start = _gnc_inliers(graph, fixes, config, initial, calibration)
    kept = [fix for fix, ok in zip(fixes, inlier, strict=True) if ok]
    final = graph.with_fixes(kept, start=keep_start, breaks=False)
    solution = smooth_pose_graph(final, config, initial=initial, calibration=calibration)
    records = list(records)
    for n, ok in zip(chosen, inlier, strict=True):
        r = records[n]
        if ok and not r.accepted:
            records[n] = dataclasses.replace(r, status=FixStatus.ACCEPTED,
                                             detail=f"kept by the robust solve (online: {r.status.value})")
        elif not ok:
            records[n] = dataclasses.replace(
                r, status=FixStatus.OUTLIER,
                detail="inconsistent with the other fixes and the dead reckoning (robust solve)")
    return solution, records, keep_start


def _gnc_inliers(graph: PoseGraph, fixes, config: GraphConfig, initial, calibration
                 ) -> tuple[np.ndarray, bool]:
    """GNC over ``fixes`` and the start's position prior, the rest of the graph (odometry without
    the online breaks, the calibration and heading priors) known inliers. Returns the fixes'
    inlier mask and whether the start prior is an inlier. The start prior stays a known inlier
    when the graph would not be determined without it."""
    base = graph.with_fixes([], start=False, breaks=False)
    plain = graph.with_fixes([], breaks=False)  # the start's prior as the model gave it
    known = base.factor_graph()
    fixed = [known.at(i) for i in range(known.size())]
    start = graph.start is not None
    keys = {int(f[0]) for f in fixes}

    def candidate(i: int, weight: float):
        if i < len(fixes):
            key, position, cov = fixes[i]
            return base.fix_factor(key, position, np.asarray(cov) / weight, kernel="none")
        return plain.start_factor(weight)

    full = graph.with_fixes(fixes, breaks=False)
    values = full.values(initial, calibration)
    ordering = _ordering(full.factor_graph(), graph.calibrated)

    def solve(factors, values):
        if graph.calibrated:
            return _gauss_newton(factors, values, ordering, config.max_iterations)[0]
        optimizer = _optimizer(factors, values, config, ordering)
        return optimizer.optimize()

    as_candidate = start and len(keys) >= 2  # with fewer fixes the start is all there is
    if not as_candidate and start:
        fixed.append(plain.start_factor())
    try:
        result = gnc(fixed, candidate, len(fixes) + int(as_candidate), values, solve,
                     probability=config.gnc_probability)
    except RuntimeError as exc:  # a weighted graph GTSAM finds indeterminant
        if not as_candidate:
            raise _translate(exc, graph) from None
        fixed.append(plain.start_factor())
        try:
            result = gnc(fixed, candidate, len(fixes), values, solve, probability=config.gnc_probability)
        except RuntimeError as again:
            raise _translate(again, graph) from None
        as_candidate = False
    inlier = result.inliers[: len(fixes)]
    keep_start = not as_candidate or bool(result.inliers[-1])
    if not keep_start and len({int(f[0]) for f, ok in zip(fixes, inlier, strict=True) if ok}) < 2:
        keep_start = True  # nothing else would tie the graph to the map
    return inlier, keep_start


def _frame_poses(world_pose, calibration, origin) -> np.ndarray:
    """DR-frame poses of world poses (the inverse of :func:`~tangraph.graph.calibration.to_world`)."""
    k, b = float(calibration[0]), float(calibration[1])
    d = np.asarray(world_pose, float)[..., :2] - origin
    out = np.array(world_pose, float)
    out[..., :2] = origin + (1.0 + k) * (d @ rotation_matrix(b).T)
    out[..., 2] = out[..., 2] + b
    return out


#: A sounding whose standardised residual is beyond this is left out of the terrain solve
#: (two-sided 0.999 of a normal): where the map or the sounding is wrong.
SOUNDING_GATE = 3.29
_GATE_ROUNDS = 5  # re-gating rounds of the terrain solve at most
#: Windows of track (m) whose mean residuals test the soundings' variances after a solve, as
#: check lines test a map (:func:`tangraph.eval.map_check.window_scores`)
WINDOW = 50.0
_FACTOR_ROUNDS = 4  # solves at most while the variance factor the windows show still moves


def _terrain_solve(nav: GraphNavigator, start_kept: bool, solution: SmootherSolution,
                   config: GraphConfig) -> tuple[SmootherSolution, dict]:  # fmt: skip
    """The batch solve with every sounding as a terrain factor instead of the fixes
    (:mod:`tangraph.graph.terrain_factors`), from ``solution``, on a key pose at every ping
    (:func:`_ping_graph`: the white DR noise between pings is then the odometry's, correlations
    and all): Gauss-Newton on the odometry, the priors (the start's if the robust solve kept
    it), the tide's and the soundings, the soundings re-gated at each converged solve. Returns
    the solution (its keys every ping) and what it used."""
    started = _time.perf_counter()
    fixes_solution = solution
    graph = _ping_graph(nav)
    terrain = terrain_factors.ping_terrain(nav.survey, nav.bathymetry, nav.model, graph.keys, nav.white,
                                           nav.origin, graph.calibrated)
    factors = graph.with_fixes([], start=start_kept).factor_graph()
    world, world_cov = dense_track(nav.survey, nav.white, solution, nav.origin)
    # the soundings are judged as innovations of the fixes' solution, whose uncertainty this is
    prior = np.where(np.isfinite(world_cov[:, :2, :2]), world_cov[:, :2, :2], 0.0)
    initial = _frame_poses(world, solution.calibration, nav.origin) if graph.calibrated else world
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
    used = terrain_factors.gate(terrain, nav.bathymetry, *state, SOUNDING_GATE, prior)
    if not used.any():  # nothing ties c and the tide to the poses (and METIS fails on that)
        log.warning("terrain solve: no sounding fits the map within %.2f sigma; the fixes' solution "
                    "is kept", SOUNDING_GATE)
        return fixes_solution, {"soundings": int(np.isfinite(terrain.depth).sum()), "soundings_used": 0,
                                "tide": float(terrain.tide), "variance_factor": 1.0}
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
    if config.smoother_covariance == "all":
        extra = terrain_factors.linear_factors(terrain, nav.bathymetry, pose, calibration, tide, used)
        cov, calib_cov = _marginals(factors, values, keys, ordering, graph.calibrated, extra)
        cov = joint_in_frame(pose[:, 2], cov)
    error = factors.error(values) + terrain_factors.terrain_cost(terrain, nav.bathymetry, *state, used)
    timings = {"solve": solved - started, "marginals": _time.perf_counter() - solved}
    used_info = {"soundings": int(np.isfinite(terrain.depth).sum()), "soundings_used": int(used.sum()),
                 "tide": float(tide), "variance_factor": factor}
    return SmootherSolution(keys, pose, cov, calibration if graph.calibrated else np.zeros(2), calib_cov,
                            iterations, float(error), timings), used_info


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
        ordering = _shared_last(gtsam.Ordering.MetisGaussianFactorGraph(linear))
        values, n = _gauss_newton(factors, values, ordering, config.max_iterations,
                                  **_terrain_terms(terrain, bathymetry, used, reference))
        iterations += n
        state = _unpack(values, terrain, reference)
        regated = terrain_factors.gate(terrain, bathymetry, *state, SOUNDING_GATE, prior)
        if np.array_equal(regated, used) or not regated.any():
            break
        used = regated
    return values, used, ordering, iterations


def _terrain_terms(terrain, bathymetry, used, reference) -> dict:
    """The soundings ``used`` as :func:`_gauss_newton`'s extra cost and linear factors."""

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
    survey, model, c = nav.survey, nav.model, nav.config
    shrink = np.sqrt(max(len(nav.graph.keys) - 1, 1) / max(survey.n_pings - 1, 1))
    graph = PoseGraph(nav.graph.calibration_std, nav.graph.calibration_mean, nav.origin, c.robust_kernel,
                      c.robust_parameter, c.odometry_min_std * shrink, c.odometry_min_heading_std * shrink)
    for k in range(survey.n_pings):
        graph.add_pose(k, survey.time[k], survey.dr_pose[k])
    graph.add_start(0, survey.dr_pose[0], model.initial_position_std,
                    max(model.heading_noise, c.odometry_min_heading_std))  # as the forward pass's
    ping = np.arange(survey.n_pings)
    delta, cov = increments(nav.white, survey.time, survey.dr_pose, ping[:-1], ping[1:])
    for k in range(survey.n_pings - 1):
        graph.add_odometry(k, k + 1, delta[k], cov[k])
    return graph


def _unpack(values, terrain, reference) -> tuple[np.ndarray, np.ndarray, float]:
    """Key poses (headings unwrapped near ``reference``), calibration and tide of ``values``."""
    pose = np.array(gtsam.utilities.extractPose2(values), float)
    pose[:, 2] = reference[:, 2] + _wrap(pose[:, 2] - reference[:, 2])
    calibration = np.asarray(values.atVector(CALIBRATION), float) if terrain.calibrated else np.zeros(2)
    tide = float(values.atVector(TIDE)[0]) if terrain.estimates_tide else terrain.tide
    return pose, calibration, tide


def smooth_survey(survey: Survey, bathymetry: BathymetryMap, config: GraphConfig | None = None, *,
                  model: NavigationModel | None = None, progress: bool = False) -> Track:
    """Re-navigate a recorded survey with a batch smoother over all key poses and fixes.

    A forward pass of :class:`~tangraph.graph.GraphNavigator` makes and gates the fixes; the whole
    graph, the DR's calibration included, is then solved at once (:func:`smooth_pose_graph`).
    With ``GraphConfig.robust_solve="gnc"`` (the default) the fixes the forward pass accepted,
    gated or held, and the start prior, are weighed by graduated non-convexity
    (:mod:`tangraph.graph.robust`) and the graph is solved with the inliers alone, the online
    pass's breaks undone. Re-matching around the smoothed track follows
    (``GraphConfig.rematch_iterations``), and the ping-rate track is recovered from the key poses
    and the DR (:func:`dense_track`).

    Parameters
    ----------
    survey : Survey
    bathymetry : BathymetryMap
    config : GraphConfig, optional
    model : NavigationModel, optional
        By default the one of a simulated survey (a TangraphError asks for one otherwise).
    progress : bool
        Show a progress bar for the forward pass.

    Returns
    -------
    Track
        ``method="smoother"``; ``meta`` has ``fixes``, ``n_fixes_accepted``, ``n_fixes_rejected``,
        ``key_indices``, ``calibration`` (smoothed: ``speed_scale``, ``heading_bias``,
        ``heading_error`` at the last ping, with stds), ``rematch_iterations`` (re-matches run),
        ``optimizer_iterations``, ``start_prior`` (``"kept"``, or ``"outlier"`` when the robust
        solve found the start wrong), ``lost_steps`` (the pings after the last fix kept, when the
        forward pass was lost to the end), ``lost_episodes`` (the forward pass's episodes those
        pings belong to) and ``forward_lost_episodes`` (all of the forward pass's).
    """
    started = _time.perf_counter()
    if isinstance(config, GraphConfig) and config.front_end != "tap":  # the online graph's only
        config = dataclasses.replace(config, front_end="tap")
    nav = GraphNavigator(survey, bathymetry, config, model=model).run(progress)
    forward = _time.perf_counter()
    config = nav.config
    graph = nav.graph
    initial = _frame_poses(nav.pose[graph.keys], nav.calibration, nav.origin) if graph.calibrated \
        else nav.pose[graph.keys]
    solution, records, start_kept = _solve(graph, nav.fixes, config, initial, nav.calibration)
    dense = dense_track(survey, nav.white, solution, nav.origin)
    rounds = 0
    for rounds in range(1, config.rematch_iterations + 1):
        remade = _rematch(nav, dense[0], dense[1], solution)
        new_solution, new_records, new_start = _solve(graph, remade, config, solution.pose,
                                                      solution.calibration)
        if not _moved(records, new_records, config.rematch_tolerance):
            rounds -= 1
            break
        solution, records, start_kept = new_solution, new_records, new_start
        dense = dense_track(survey, nav.white, solution, nav.origin)
        log.info("re-match %d: %d fixes accepted", rounds, sum(r.accepted for r in records))
    soundings = None
    if config.smoother_terrain == "soundings":
        solution, soundings = _terrain_solve(nav, start_kept, solution, config)
        dense = dense_track(survey, nav.white, solution, nav.origin)
        log.info("terrain solve: %d of %d soundings used", soundings["soundings_used"],
                 soundings["soundings"])
    pose, cov = dense
    if config.smoother_covariance == "none":
        cov = np.full_like(cov, np.nan)
    n_accepted = sum(r.accepted for r in records)
    meta = nav.meta()
    last = survey.n_pings - 1
    joint = np.zeros((5, 5))
    joint[3:, 3:] = solution.calibration_cov
    if config.smoother_covariance == "all" and solution.keys[-1] == last:
        joint = solution.covariance[-1]
    last_inlier = max((r.index for r in records if r.accepted), default=-1)
    tails = [e for e in nav.episodes  # never relocalised online and no fix kept after
             if e.end is None and max(e.start, last_inlier + 1) < survey.n_pings]
    lost = sorted({p for e in tails for p in range(max(e.start, last_inlier + 1), survey.n_pings)})
    meta.update({
        "n_lost": len(lost),
        "lost_steps": lost,
        "lost_episodes": [e.as_dict() for e in tails],
        "forward_lost_episodes": meta["lost_episodes"],
        "fixes": records,
        "n_fixes_accepted": int(n_accepted),
        "n_fixes_rejected": len(records) - int(n_accepted),
        "calibration": calibration_summary(solution.calibration, joint, solution.pose[-1],
                                           survey.dr_pose[last, 2]),
        "rematch_iterations": int(rounds),
        "start_prior": "kept" if start_kept else "outlier",
        "optimizer_iterations": solution.iterations,
        "final_error": solution.error,
        "terrain": config.smoother_terrain,
    })
    if soundings is not None:
        meta["soundings"] = soundings
    total = _time.perf_counter() - started
    timings = {"total": total, "per_step": total / survey.n_pings, "forward_pass": forward - started,
               **solution.timings}
    return Track(time=survey.time, pose=pose, covariance=cov, method="smoother", timings=timings, meta=meta)
