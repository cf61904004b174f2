"""Batch smoother: every key pose and factor of a recorded survey solved at once.

The factors come from a forward pass of :class:`~tangraph.graph.GraphNavigator` (its fixes were
searched and gated online). Levenberg-Marquardt (or Gauss-Newton, dogleg) solves the whole
graph with METIS ordering: the default COLAMD ordering makes an elimination tree as deep as the
chain, which overflows the stack on chains of about 10^5 poses. The marginal covariance of every
key pose comes from one multifrontal elimination of the linearised graph, also ordered by METIS
(``gtsam.Marginals`` cannot be given an ordering from Python and crashes on such chains).

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
from tangraph.graph.config import GraphConfig
from tangraph.graph.factors import compose, inverse_increment_covariance, propagate, tangent_to_world
from tangraph.graph.fixes import failed, judge_fix, make_fix, search_half_width
from tangraph.graph.keyposes import PoseGraph, increments
from tangraph.graph.online import GraphNavigator, _translate, _wrap
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import MatchingError
from tangraph.sensors import DeadReckoningModel, odometry
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["SmootherSolution", "dense_track", "smooth_pose_graph", "smooth_survey"]

log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, eq=False)
class SmootherSolution:
    """Key poses ``(n, 3)`` and world covariances ``(n, 3, 3)`` (NaN if not computed) of a batch solve."""

    keys: np.ndarray
    pose: np.ndarray
    covariance: np.ndarray
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
                      initial=None) -> SmootherSolution:
    """Solve a whole :class:`~tangraph.graph.keyposes.PoseGraph` (METIS ordering).

    Parameters
    ----------
    graph : PoseGraph
    config : GraphConfig, optional
        ``optimizer``, ``max_iterations`` and ``smoother_covariance`` are used.
    initial : array_like (n_keys, 3), optional
        Initial key poses (default: those stored in the graph).

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
    factors, values = graph.factor_graph(), graph.values(initial)
    started = _time.perf_counter()
    try:
        ordering = gtsam.Ordering.MetisNonlinearFactorGraph(factors)
        optimizer = _optimizer(factors, values, config, ordering)
        result = optimizer.optimize()
    except (RuntimeError, IndexError) as exc:  # GTSAM's indeterminant system; METIS on odd graphs
        raise _translate(exc, graph) from None
    solved = _time.perf_counter()
    keys = np.asarray(graph.keys, np.int64)
    pose = np.array(gtsam.utilities.extractPose2(result), float)  # in key order: the pings ascending
    if initial is None:
        initial = np.asarray(graph.initial)
    pose[:, 2] = np.asarray(initial)[:, 2] + _wrap(pose[:, 2] - np.asarray(initial)[:, 2])
    cov = np.full((keys.size, 3, 3), np.nan)
    if config.smoother_covariance == "all":
        cov = tangent_to_world(pose[:, 2], _marginals(factors, result, keys, ordering))
    done = _time.perf_counter()
    return SmootherSolution(keys, pose, cov, int(optimizer.iterations()), float(factors.error(result)),
                            {"solve": solved - started, "marginals": done - solved})


def _marginals(factors, result, keys, ordering) -> np.ndarray:
    """Marginal covariances (tangent) of ``keys`` from one METIS-ordered multifrontal elimination."""
    linear = factors.linearize(result)
    try:
        tree = linear.eliminateMultifrontal(ordering)
    except RuntimeError as exc:
        raise TangraphError(f"marginal covariances failed: {str(exc).strip().splitlines()[0]}") from None
    return np.array([tree.marginalCovariance(int(k)) for k in keys])


def dense_track(survey: Survey, dr_model: DeadReckoningModel, keys, key_pose, key_cov, *,
                scale_noise: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Poses ``(K, 3)`` and world covariances ``(K, 3, 3)`` at every ping from smoothed key poses.

    Between keys ``a < b`` a ping is predicted forward from ``a`` and backward from ``b`` with the
    DR increments; poses and covariances are blended with weight ``(t - t_a) / (t_b - t_a)``.
    """
    keys = np.asarray(keys, np.int64)
    t, dr = survey.time, survey.dr_pose
    ping = np.arange(survey.n_pings)
    n_key = np.searchsorted(keys, ping, side="right") - 1
    a = keys[n_key]
    b = keys[np.minimum(n_key + 1, keys.size - 1)]
    b = np.where(a == ping, ping, b)
    ia, ib = n_key, np.searchsorted(keys, b)
    fwd, fwd_q = increments(dr_model, t, dr, a, ping, scale_noise=scale_noise)
    back_q = increments(dr_model, t, dr, ping, b, scale_noise=scale_noise)[1]
    back = odometry(dr, b, ping)
    back_q = inverse_increment_covariance(back, back_q)
    pose_f, pose_b = compose(key_pose[ia], fwd), compose(key_pose[ib], back)
    cov_f = propagate(key_pose[ia], key_cov[ia], fwd, fwd_q)
    cov_b = propagate(key_pose[ib], key_cov[ib], back, back_q)
    span = t[b] - t[a]
    w = np.divide(t - t[a], span, out=np.zeros_like(t), where=span > 0)
    pose = pose_f + w[:, None] * np.column_stack([pose_b[:, :2] - pose_f[:, :2],
                                                  _wrap(pose_b[:, 2] - pose_f[:, 2])])
    cov = (1 - w)[:, None, None] * cov_f + w[:, None, None] * cov_b
    return pose, cov


def _rematch(nav: GraphNavigator, pose, cov, previous: list[dict]) -> tuple[list[dict], list, bool]:
    """Fixes re-made around the smoothed track; returns records, accepted fixes and whether they moved."""
    config = nav.config
    records, accepted = [], []
    changed = False
    before = {r["index"]: r for r in previous}
    for end in nav.fix_ends:
        half_width = search_half_width(config, nav.bathymetry, cov[end, :2, :2])
        try:
            fix = make_fix(nav.survey, nav.bathymetry, int(end), config, pose[end, :2], half_width,
                           poses=pose[int(end) - config.n_pings + 1 : int(end) + 1])
            outcome = judge_fix(nav._grown(fix), pose[end], cov[end], config, half_width)
        except MatchingError as exc:
            outcome = failed(int(end), exc, half_width)
        except TangraphError as exc:
            outcome = failed(int(end), exc, half_width)
            outcome.record["reason"] = f"invalid covariance: {exc}"
        records.append(outcome.record)
        if outcome.accepted:
            accepted.append((int(end), np.asarray(outcome.fix.position, float),
                             np.asarray(outcome.fix.covariance, float)))
        old = before.get(int(end))
        if old is None or old["accepted"] != outcome.record["accepted"]:
            changed = True
        elif outcome.accepted and np.hypot(old["north"] - outcome.record["north"],
                                           old["east"] - outcome.record["east"]) > config.rematch_tolerance:
            changed = True
    return records, accepted, changed


def smooth_survey(survey: Survey, bathymetry: BathymetryMap, config: GraphConfig | None = None, *,
                  dr_model: DeadReckoningModel | None = None, progress: bool = False) -> Track:
    """Re-navigate a recorded survey with a batch smoother over all key poses and fixes.

    A forward pass of :class:`~tangraph.graph.GraphNavigator` makes and gates the fixes; the whole
    graph is then solved at once (:func:`smooth_pose_graph`), with optional re-matching around the
    smoothed track (``GraphConfig.rematch_iterations``), and the ping-rate track is recovered
    from the key poses and the DR (:func:`dense_track`).

    Parameters
    ----------
    survey : Survey
    bathymetry : BathymetryMap
    config : GraphConfig, optional
    dr_model : DeadReckoningModel, optional
        By default the one a simulated survey records (a TangraphError asks for one otherwise).
    progress : bool
        Show a progress bar for the forward pass.

    Returns
    -------
    Track
        ``method="smoother"``; ``meta`` has ``fixes``, ``n_fixes_accepted``, ``n_fixes_rejected``,
        ``key_indices``, ``rematch_iterations`` (re-matches run) and ``optimizer_iterations``.
    """
    started = _time.perf_counter()
    nav = GraphNavigator(survey, bathymetry, config, dr_model=dr_model).run(progress)
    forward = _time.perf_counter()
    config = nav.config
    graph = nav.graph
    solution = smooth_pose_graph(graph, config, initial=nav.pose[graph.keys])
    records = nav.fixes
    dense = dense_track(survey, nav.dr_model, solution.keys, solution.pose, _usable(solution.covariance),
                        scale_noise=config.odometry_scale_noise)
    rounds = 0
    for rounds in range(1, config.rematch_iterations + 1):
        new_records, accepted, changed = _rematch(nav, dense[0], dense[1], records)
        if not changed:
            rounds -= 1
            break
        records = new_records
        graph = graph.with_fixes(accepted)
        solution = smooth_pose_graph(graph, config, initial=solution.pose)
        dense = dense_track(survey, nav.dr_model, solution.keys, solution.pose, _usable(solution.covariance),
                            scale_noise=config.odometry_scale_noise)
        log.info("re-match %d: %d fixes accepted", rounds, len(accepted))
    pose, cov = dense
    if config.smoother_covariance == "none":
        cov = np.full_like(cov, np.nan)
    n_accepted = sum(r["accepted"] for r in records)
    meta = nav.meta()
    meta.update({
        "fixes": records,
        "n_fixes_accepted": int(n_accepted),
        "n_fixes_rejected": len(records) - int(n_accepted),
        "rematch_iterations": int(rounds),
        "optimizer_iterations": solution.iterations,
        "final_error": solution.error,
    })
    total = _time.perf_counter() - started
    timings = {"total": total, "per_step": total / survey.n_pings, "forward_pass": forward - started,
               **solution.timings}
    return Track(time=survey.time, pose=pose, covariance=cov, method="smoother", timings=timings, meta=meta)


def _usable(cov: np.ndarray) -> np.ndarray:
    """Covariances for re-matching and the dense track; zeros stand in for ones not computed."""
    return np.where(np.isfinite(cov), cov, 0.0)

