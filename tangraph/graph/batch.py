"""The batch solve's pieces: its solution, Gauss-Newton on a GTSAM graph, the METIS ordering,
the marginal covariances and the ping-rate track.

Shared by the smoother on the fixes (:mod:`tangraph.graph.smoother`) and on every sounding
(:mod:`tangraph.graph.terrain_solve`).

The ping-rate track is recovered from the key poses and the DR: a ping between keys ``a`` and
``b`` is predicted forward from ``a`` and backward from ``b`` by the DR increments, and the two
are blended linearly in time (the correction is distributed between the neighbouring keys); its
covariance is the same blend of the two propagated covariances.
"""

from __future__ import annotations

import dataclasses

import gtsam
import numpy as np

from tangraph.errors import TangraphError
from tangraph.geometry import to_dr_frame, wrap_angle
from tangraph.graph.calibration import CALIBRATION, TIDE, to_world, world_covariance
from tangraph.graph.factors import compose, inverse_increment_covariance, propagate_joint
from tangraph.graph.keyposes import increments
from tangraph.sensors import DeadReckoningModel, odometry
from tangraph.survey import Survey

__all__ = ["SmootherSolution", "dense_track", "frame_poses", "gauss_newton", "marginals", "metis_ordering",
           "shared_last"]


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


def gauss_newton(factors, values, ordering, max_iterations: int, tolerance: float = 1e-6, *,
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


def metis_ordering(factors, calibrated: bool):
    """METIS ordering, with the calibration (joined to every fix) and the tide (joined to every
    terrain factor) moved to the end: eliminated early they would join all the poses they touch
    into one dense clique."""
    return shared_last(gtsam.Ordering.MetisNonlinearFactorGraph(factors))


def shared_last(metis):
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


def marginals(factors, result, keys, ordering, calibrated: bool, extra=()) -> tuple[np.ndarray, np.ndarray]:
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
                                                  wrap_angle(pose_b[:, 2] - pose_f[:, 2])])
    joint = (1 - w)[:, None, None] * cov_f + w[:, None, None] * cov_b
    return (to_world(pose, solution.calibration, origin),
            world_covariance(pose, joint, solution.calibration, origin))


def frame_poses(world_pose, calibration, origin) -> np.ndarray:
    """DR-frame poses of world poses (the inverse of :func:`~tangraph.graph.calibration.to_world`)."""
    return to_dr_frame(world_pose, calibration, origin)
