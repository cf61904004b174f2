"""Factors of the pose graph, their noise models, and the frames their covariances live in.

GTSAM poses are ``Pose2(x=north, y=east, theta=psi)``, so ``Pose2.compose`` and
:func:`tangraph.sensors.odometry` agree: an increment ``(forward, starboard, dpsi)`` in the frame of
pose ``i`` composed onto pose ``i`` gives pose ``j``. Three frames of a 3 x 3 covariance appear:

- *world*: ``(north, east, psi)``, what a :class:`~tangraph.track.Track` holds;
- *tangent* of a pose (GTSAM's local coordinates): the position part in the pose's body frame,
  what ``Marginals`` and ``ISAM2.marginalCovariance`` return and what a ``PriorFactorPose2``'s
  noise model means; ``world = A tangent A^T`` with ``A = blkdiag(R(psi), 1)``;
- *increment*: :func:`tangraph.sensors.increment_covariance`, the position part in the frame of
  pose ``i``. A ``BetweenFactorPose2``'s error ``Log(z^-1 h(x))`` is, to first order, the
  increment error turned into the frame of pose ``j``: ``blkdiag(R(-dpsi), 1)``.

A position fix is a ``PoseTranslationPrior2D``: its error ``t - z`` is in the world frame.
"""

from __future__ import annotations

from typing import Any

import gtsam
import numpy as np

from tangraph.errors import TangraphError
from tangraph.geometry import compose, mahalanobis2, rotation_matrix  # compose: re-exported

__all__ = [
    "between_noise",
    "check_fix_covariance",
    "compose",
    "inverse_increment_covariance",
    "nis",
    "pose_prior_factor",
    "position_fix_factor",
    "propagate",
    "propagate_joint",
    "robust_noise",
    "tangent_to_world",
    "world_to_tangent",
]


def _blk_rotation(psi) -> np.ndarray:
    """``blkdiag(R(psi), 1)`` for an array of headings, shape ``(..., 3, 3)``."""
    psi = np.asarray(psi, float)
    a = np.zeros((*psi.shape, 3, 3))
    a[..., :2, :2], a[..., 2, 2] = rotation_matrix(psi), 1.0
    return a


def tangent_to_world(psi, cov) -> np.ndarray:
    """A pose covariance in GTSAM's local coordinates at heading ``psi`` turned into the world frame."""
    a = _blk_rotation(psi)
    return a @ np.asarray(cov, float) @ np.swapaxes(a, -1, -2)


def world_to_tangent(psi, cov) -> np.ndarray:
    """Inverse of :func:`tangent_to_world`."""
    a = _blk_rotation(psi)
    return np.swapaxes(a, -1, -2) @ np.asarray(cov, float) @ a


def between_noise(increment, cov, min_std: float, min_heading_std: float) -> np.ndarray:
    """Covariances ``(..., 3, 3)`` of ``BetweenFactorPose2`` errors from increment covariances.

    The increment covariance (frame of pose ``i``) is floored by ``min_std**2`` on each position
    axis and ``min_heading_std**2`` on the heading, then turned into the frame of pose ``j``.
    """
    cov = np.array(cov, float)
    cov = 0.5 * (cov + np.swapaxes(cov, -1, -2))
    cov[..., 0, 0] += min_std**2
    cov[..., 1, 1] += min_std**2
    cov[..., 2, 2] += min_heading_std**2
    return world_to_tangent(np.asarray(increment, float)[..., 2], cov)


def inverse_increment_covariance(inverse, cov) -> np.ndarray:
    """Covariance ``(..., 3, 3)`` of the SE(2) inverse ``d^-1`` of an increment ``d`` whose
    covariance is ``cov`` (frame of ``d``'s start), given the inverse ``(..., 3)`` itself.

    ``d^-1 = (-R(-dpsi) t, -dpsi)``, so its Jacobian is ``[[-R(psi'), (y', -x')^T], [0, 0, -1]]``
    with ``(x', y', psi') = d^-1``: the heading error of the increment moves the inverse's
    position by its lever arm, which a rotation alone would miss.
    """
    inverse = np.asarray(inverse, float)
    jac = np.zeros((*inverse.shape[:-1], 3, 3))
    jac[..., :2, :2] = -rotation_matrix(inverse[..., 2])
    jac[..., 0, 2], jac[..., 1, 2], jac[..., 2, 2] = inverse[..., 1], -inverse[..., 0], -1.0
    return jac @ np.asarray(cov, float) @ np.swapaxes(jac, -1, -2)


def propagate(pose, cov, increment, increment_cov) -> np.ndarray:
    """World covariance of ``pose (+) increment``: the pose's world covariance ``cov`` carried by
    the first-order Jacobian, plus the increment covariance (frame of ``pose``) turned into the world.
    """
    return propagate_joint(pose, cov, increment, increment_cov)


def propagate_joint(pose, joint, increment, increment_cov) -> np.ndarray:
    """:func:`propagate` for a joint covariance ``(..., n, n)`` (``n >= 3``) whose first three
    coordinates are the pose's world coordinates and whose others (the calibration) do not move."""
    pose, increment = np.asarray(pose, float), np.asarray(increment, float)
    joint = np.asarray(joint, float)
    n = joint.shape[-1]
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    j = np.zeros((*pose.shape[:-1], n, n))
    j[..., np.arange(n), np.arange(n)] = 1.0
    j[..., 0, 2] = -s * increment[..., 0] - c * increment[..., 1]
    j[..., 1, 2] = c * increment[..., 0] - s * increment[..., 1]
    a = _blk_rotation(pose[..., 2])
    out = j @ joint @ np.swapaxes(j, -1, -2)
    out[..., :3, :3] += a @ np.asarray(increment_cov, float) @ np.swapaxes(a, -1, -2)
    return out


def robust_noise(cov: np.ndarray, kernel: str, parameter: float):
    """A Gaussian noise model of covariance ``cov``, wrapped in a Huber or Cauchy M-estimator."""
    base = gtsam.noiseModel.Gaussian.Covariance(np.asarray(cov, float))
    if kernel == "none":
        return base
    kinds: dict[str, Any] = {"huber": gtsam.noiseModel.mEstimator.Huber,
                             "cauchy": gtsam.noiseModel.mEstimator.Cauchy}
    estimator = kinds[kernel].Create(float(parameter))
    return gtsam.noiseModel.Robust.Create(estimator, base)


def check_fix_covariance(cov, name: str) -> np.ndarray:
    """``cov`` as a symmetric positive-definite 2 x 2 array, else a TangraphError naming the fix."""
    c = np.asarray(cov, float)
    if c.shape != (2, 2):
        raise TangraphError(f"{name}: covariance must be 2 x 2, got shape {c.shape}")
    if not np.all(np.isfinite(c)):
        raise TangraphError(f"{name}: covariance is not finite: {c.tolist()}")
    if not np.allclose(c, c.T, rtol=1e-6, atol=1e-12 * max(1.0, float(np.abs(c).max()))):
        raise TangraphError(f"{name}: covariance is not symmetric: {c.tolist()}")
    c = 0.5 * (c + c.T)
    low = float(np.linalg.eigvalsh(c).min())
    if not low > 1e-12 * max(1.0, float(np.trace(c))):
        raise TangraphError(
            f"{name}: covariance is not positive definite (smallest eigenvalue {low:.3g}): {c.tolist()}"
        )
    return c


def position_fix_factor(key: int, position, cov, kernel: str, parameter: float):
    """The translation prior ``PoseTranslationPrior2D`` of a fix on pose ``key``."""
    return gtsam.PoseTranslationPrior2D(int(key), np.asarray(position, float),
                                        robust_noise(cov, kernel, parameter))


def pose_prior_factor(key: int, pose, cov_world):
    """A ``PriorFactorPose2`` on ``key`` at ``pose`` with a world-frame covariance."""
    pose = np.asarray(pose, float)
    cov = world_to_tangent(pose[2], np.asarray(cov_world, float))
    return gtsam.PriorFactorPose2(int(key), gtsam.Pose2(*pose), gtsam.noiseModel.Gaussian.Covariance(cov))


def nis(error, cov) -> float:
    """Normalised innovation squared ``e^T C^-1 e``."""
    return float(mahalanobis2(error, cov))


