"""Batch smoother: every key pose and factor of a recorded survey solved at once.

The factors come from a forward pass of :class:`~tangraph.graph.GraphNavigator` (its fixes were
searched and gated online). Gauss-Newton with step halving
(:func:`~tangraph.graph.batch.gauss_newton`) solves the whole graph with METIS ordering: the
default COLAMD ordering makes an elimination tree as deep as the chain, which overflows the
stack on chains of about 10^5 poses. The marginal covariance of every
key pose comes from one multifrontal elimination of the linearised graph, also ordered by METIS
(``gtsam.Marginals`` cannot be given an ordering from Python and crashes on such chains).

With ``GraphConfig.batch.smoother_terrain = "soundings"`` (or ``"field"``) a last solve replaces the
fixes by every sounding (:mod:`tangraph.graph.terrain_solve`). The ping-rate track is recovered
from the key poses and the DR (:func:`~tangraph.graph.batch.dense_track`).
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time

import gtsam
import numpy as np

from tangraph.errors import TangraphError
from tangraph.fix_records import FixRecord, FixStatus
from tangraph.geometry import wrap_near
from tangraph.graph.batch import (
    SmootherSolution,
    dense_track,
    frame_poses,
    gauss_newton,
    marginals,
    metis_ordering,
)
from tangraph.graph.calibration import CALIBRATION, calibration_summary, joint_in_frame
from tangraph.graph.config import GraphConfig
from tangraph.graph.fixes import failed, judge_fix, make_fix, search_half_width
from tangraph.graph.keyposes import PoseGraph, translate_error
from tangraph.graph.online import GraphNavigator
from tangraph.graph.robust import gnc
from tangraph.graph.terrain_solve import terrain_solve
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import MatchingError
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["SmootherSolution", "dense_track", "smooth_pose_graph", "smooth_survey"]

log = logging.getLogger(__name__)

def smooth_pose_graph(graph: PoseGraph, config: GraphConfig | None = None, *,
                      initial=None, calibration=None) -> SmootherSolution:
    """Solve a whole :class:`~tangraph.graph.keyposes.PoseGraph` (METIS ordering).

    Parameters
    ----------
    graph : PoseGraph
    config : GraphConfig, optional
        ``max_iterations`` and ``smoother_covariance`` are used.
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
        ordering = metis_ordering(factors, graph.calibrated)
        result, iterations = gauss_newton(factors, values, ordering, config.batch.max_iterations)
    except (RuntimeError, IndexError) as exc:  # GTSAM's indeterminant system; METIS on odd graphs
        raise translate_error(exc, graph) from None
    solved = _time.perf_counter()
    keys = np.asarray(graph.keys, np.int64)
    pose = np.array(gtsam.utilities.extractPose2(result), float)  # in key order: the pings ascending
    if initial is None:
        initial = np.asarray(graph.initial)
    pose[:, 2] = wrap_near(pose[:, 2], np.asarray(initial)[:, 2])
    calib = np.zeros(2)
    if graph.calibrated:
        calib = np.asarray(result.atVector(CALIBRATION), float)
    cov = np.full((keys.size, 5, 5), np.nan)
    calib_cov = np.zeros((2, 2))
    if config.batch.smoother_covariance == "all":
        cov, calib_cov = marginals(factors, result, keys, ordering, graph.calibrated)
        cov = joint_in_frame(pose[:, 2], cov)
    done = _time.perf_counter()
    timings = {"solve": solved - started, "marginals": done - solved}
    return SmootherSolution(keys, pose, cov, calib, calib_cov, iterations,
                            float(factors.error(result)), timings)

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
                           error=nav.map_error, drift=nav.fix_drift)
            laid = None if window.start < 0 else frame_poses(pose[window], solution.calibration, nav.origin)
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
    if config.batch.robust_solve != "gnc":
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
    ordering = metis_ordering(full.factor_graph(), graph.calibrated)

    def solve(factors, values):
        return gauss_newton(factors, values, ordering, config.batch.max_iterations)[0]

    as_candidate = start and len(keys) >= 2  # with fewer fixes the start is all there is
    if not as_candidate and start:
        fixed.append(plain.start_factor())
    try:
        result = gnc(fixed, candidate, len(fixes) + int(as_candidate), values, solve,
                     probability=config.batch.gnc_probability)
    except RuntimeError as exc:  # a weighted graph GTSAM finds indeterminant
        if not as_candidate:
            raise translate_error(exc, graph) from None
        fixed.append(plain.start_factor())
        try:
            result = gnc(fixed, candidate, len(fixes), values, solve,
                         probability=config.batch.gnc_probability)
        except RuntimeError as again:
            raise translate_error(again, graph) from None
        as_candidate = False
    inlier = result.inliers[: len(fixes)]
    keep_start = not as_candidate or bool(result.inliers[-1])
    if not keep_start and len({int(f[0]) for f, ok in zip(fixes, inlier, strict=True) if ok}) < 2:
        keep_start = True  # nothing else would tie the graph to the map
    return inlier, keep_start


def _smoothed_meta(nav: GraphNavigator, solution: SmootherSolution, records, rounds: int,
                   start_kept: bool) -> dict:
    """The smoothed track's ``meta`` (see :func:`smooth_survey`): the forward pass's, with the
    fixes the solve kept, the calibration it found and the pings lost to the end (those of the
    forward pass's episodes never relocalised that no kept fix follows)."""
    survey, config = nav.survey, nav.config
    n_accepted = sum(r.accepted for r in records)
    meta = nav.meta()
    last = survey.n_pings - 1
    joint = np.zeros((5, 5))
    joint[3:, 3:] = solution.calibration_cov
    if config.batch.smoother_covariance == "all" and solution.keys[-1] == last:
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
        "n_fixes_accepted": int(n_accepted),
        "n_fixes_rejected": len(records) - int(n_accepted),
        "calibration": calibration_summary(solution.calibration, joint, solution.pose[-1],
                                           survey.dr_pose[last, 2]),
        "rematch_iterations": int(rounds),
        "start_prior": "kept" if start_kept else "outlier",
        "optimizer_iterations": solution.iterations,
        "final_error": solution.error,
        "terrain": config.batch.smoother_terrain,
    })
    return meta


def smooth_survey(survey: Survey, bathymetry: BathymetryMap, config: GraphConfig | None = None, *,
                  model: NavigationModel | None = None, progress: bool = False) -> Track:
    """Re-navigate a recorded survey with a batch smoother over all key poses and fixes.

    A forward pass of :class:`~tangraph.graph.GraphNavigator` makes and gates the fixes; the whole
    graph, the DR's calibration included, is then solved at once (:func:`smooth_pose_graph`).
    With ``GraphConfig.batch.robust_solve="gnc"`` (the default) the fixes the forward pass accepted,
    gated or held, and the start prior, are weighed by graduated non-convexity
    (:mod:`tangraph.graph.robust`) and the graph is solved with the inliers alone, the online
    pass's breaks undone. Re-matching around the smoothed track follows
    (``GraphConfig.batch.rematch_iterations``), and the ping-rate track is recovered from the key poses
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
        ``method="smoother"``; ``fixes`` the records of the fixes the solve judged; ``meta`` has
        ``n_fixes_accepted``, ``n_fixes_rejected``, ``key_indices``, ``calibration`` (smoothed:
        ``speed_scale``, ``heading_bias``, ``heading_error`` at the last ping, with stds),
        ``rematch_iterations`` (re-matches run),
        ``optimizer_iterations``, ``start_prior`` (``"kept"``, or ``"outlier"`` when the robust
        solve found the start wrong), ``lost_steps`` (the pings after the last fix kept, when the
        forward pass was lost to the end), ``lost_episodes`` (the forward pass's episodes those
        pings belong to) and ``forward_lost_episodes`` (all of the forward pass's).
    """
    started = _time.perf_counter()
    if isinstance(config, GraphConfig) and config.online.front_end != "tap":  # the online graph's only
        config = config.replace(front_end="tap")
    if isinstance(config, GraphConfig) and config.online.terrain != "fixes":  # so is its tracking
        config = config.replace(terrain="fixes", acquire="windows")
    nav = GraphNavigator(survey, bathymetry, config, model=model).run(progress)
    forward = _time.perf_counter()
    config = nav.config
    graph = nav.graph
    initial = frame_poses(nav.pose[graph.keys], nav.calibration, nav.origin) if graph.calibrated \
        else nav.pose[graph.keys]
    solution, records, start_kept = _solve(graph, nav.fixes, config, initial, nav.calibration)
    dense = dense_track(survey, nav.white, solution, nav.origin)
    rounds = 0
    for rounds in range(1, config.batch.rematch_iterations + 1):
        remade = _rematch(nav, dense[0], dense[1], solution)
        new_solution, new_records, new_start = _solve(graph, remade, config, solution.pose,
                                                      solution.calibration)
        if not _moved(records, new_records, config.batch.rematch_tolerance):
            rounds -= 1
            break
        solution, records, start_kept = new_solution, new_records, new_start
        dense = dense_track(survey, nav.white, solution, nav.origin)
        log.info("re-match %d: %d fixes accepted", rounds, sum(r.accepted for r in records))
    soundings = refined = None
    if config.batch.smoother_terrain != "fixes":
        solution, soundings, refined = terrain_solve(nav, start_kept, solution, records, config)
        dense = dense_track(survey, nav.white, solution, nav.origin)
        log.info("terrain solve: %d of %d soundings used", soundings["soundings_used"],
                 soundings["soundings"])
    pose, cov = dense
    if config.batch.smoother_covariance == "none":
        cov = np.full_like(cov, np.nan)
    meta = _smoothed_meta(nav, solution, records, rounds, start_kept)
    if soundings is not None:
        meta["soundings"] = soundings
    if refined is not None:
        meta["refined_map"] = refined
    total = _time.perf_counter() - started
    timings = {"total": total, "per_step": total / survey.n_pings, "forward_pass": forward - started,
               **solution.timings}
    return Track(time=survey.time, pose=pose, covariance=cov, method="smoother", timings=timings, meta=meta,
                 fixes=tuple(records))
