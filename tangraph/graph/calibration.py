"""The DR's constant errors in the graph: the DR frame, the calibration variable and its factors.

The dead reckoning has two constant errors (:class:`~tangraph.sensors.NavigationModel`): the DVL
reads ``1 + k`` times the true speed and the DR heading is the true heading plus ``b``. Each DR
step is then the true step turned by ``b`` and stretched by ``1 + k``, so the whole DR track is
the true track mapped by one similarity about the start ``o`` (the first DR position)::

    p' = o + (1 + k) R(b) (p - o),     psi' = psi + b.

The graph's key poses live in this *DR frame* (primed): there the DR increments are exact, so the
odometry factors are GTSAM's own ``BetweenFactorPose2`` on the DR increments, with the white DR
noise only. The calibration ``c = (k, b)`` is one variable (a 2-vector, key :data:`CALIBRATION`)
with a Gaussian prior; every factor that measures the *world* (a terrain fix, the start
position) maps the pose back with the current ``c``::

    p = o + R(-b) (p' - o) / (1 + k),   psi = psi' - b,

so it depends on the pose and on ``c`` (:func:`world_position_factor`, analytic Jacobians,
checked against numerical derivatives in the tests). This is exact, not a linearisation: the
increments of every odometry factor depend on ``c`` only through this map. A *joint* state
``y = (north', east', psi', k, b)`` (the pose in DR-frame world coordinates) and its 5 x 5
covariance carry the calibration's uncertainty to every pose the graph reports
(:func:`to_world`, :func:`world_jacobian`).
"""

from __future__ import annotations

from functools import partial

import gtsam
import numpy as np

from tangraph.geometry import from_dr_frame, rotation_matrix, wrap_angle
from tangraph.graph.factors import robust_noise

__all__ = [
    "CALIBRATION",
    "MAP_OFFSET",
    "TIDE",
    "calibration_prior_factor",
    "calibration_summary",
    "graph_calibration_std",
    "joint_in_frame",
    "position_tide_factor",
    "to_world",
    "world_covariance",
    "world_jacobian",
    "world_position",
    "world_position_factor",
]

CALIBRATION = int(gtsam.symbol("c", 0))  #: GTSAM key of the calibration ``(k, b)``
TIDE = int(gtsam.symbol("t", 0))  #: GTSAM key of the tide (a 1-vector), when the online graph holds it
#: GTSAM key of the map's horizontal offset ``(north, east)`` against the survey's frame, when the
#: smoother's field solve holds it (``NavigationModel.map_offset_std``)
MAP_OFFSET = int(gtsam.symbol("o", 0))

_J = np.array([[0.0, -1.0], [1.0, 0.0]])  # d R(a) / da = R(a) J

def graph_calibration_std(model) -> np.ndarray | None:
    """The prior std of the graph's calibration variable for a navigation ``model``: None (no
    variable: the graph trusts the DR's shape) when both constant errors are known to be zero
    (stds and means 0), else the model's stds with a known one (std 0) held at
    :data:`tangraph.sensors.KNOWN_STD` (a std of exactly 0 has no Gaussian noise model).

    >>> from tangraph.sensors import NavigationModel
    >>> graph_calibration_std(NavigationModel(speed_scale_std=0.0, heading_bias_std=0.0)) is None
    True
    >>> graph_calibration_std(NavigationModel(speed_scale_std=0.0, heading_bias_std=0.05)).tolist()
    [1e-06, 0.05]
    """
    from tangraph.sensors import KNOWN_STD

    std = np.asarray(model.calibration_std, float)
    if not np.any(std > 0) and not np.any(np.asarray(model.calibration_prior) != 0):
        return None
    return np.where(std > 0, std, KNOWN_STD)


def joint_in_frame(psi, joint) -> np.ndarray:
    """Joint covariances ``(..., n, n)`` of (pose in GTSAM's tangent coordinates, c, ...) turned
    into DR-frame world coordinates (the ``y`` of this module), ``psi`` the poses' headings."""
    psi = np.asarray(psi, float)
    n = np.shape(joint)[-1]
    a = np.zeros((*psi.shape, n, n))
    a[..., :, :] = np.eye(n)
    a[..., :2, :2] = rotation_matrix(psi)
    return a @ joint @ np.swapaxes(a, -1, -2)


def world_position(position, calibration, origin) -> np.ndarray:
    """World positions ``(..., 2)`` of DR-frame positions ``(..., 2)`` under ``c = (k, b)``."""
    return from_dr_frame(np.asarray(position, float)[..., :2], calibration, origin)


def to_world(pose, calibration, origin) -> np.ndarray:
    """World poses ``(..., 3)`` of DR-frame poses ``(..., 3)`` under ``c = (k, b)``."""
    return from_dr_frame(pose, calibration, origin)


def world_jacobian(pose, calibration, origin) -> np.ndarray:
    """Jacobians ``(..., 3, 5)`` of :func:`to_world` with respect to ``y = (north', east', psi',
    k, b)``."""
    pose = np.asarray(pose, float)
    k, b = float(calibration[0]), float(calibration[1])
    d = pose[..., :2] - np.asarray(origin, float)
    a = rotation_matrix(-b) / (1.0 + k)
    jac = np.zeros((*pose.shape[:-1], 3, 5))
    jac[..., :2, :2] = a
    jac[..., :2, 3] = -(d @ a.T) / (1.0 + k)
    jac[..., :2, 4] = -(d @ (a @ _J).T)
    jac[..., 2, 2] = 1.0
    jac[..., 2, 4] = -1.0
    return jac


def world_covariance(pose, joint_cov, calibration, origin) -> np.ndarray:
    """World covariances ``(..., 3, 3)`` of poses whose joint state ``y`` has covariance
    ``joint_cov (..., 5, 5)`` (DR-frame world coordinates)."""
    jac = world_jacobian(pose, calibration, origin)
    return jac @ np.asarray(joint_cov, float) @ np.swapaxes(jac, -1, -2)


def _position_error(origin, measured, factor, values, jacobians):
    """Error ``world position - measured`` of a pose (key 0) under the calibration (key 1)."""
    keys = factor.keys()
    pose = values.atPose2(keys[0])
    k, b = values.atVector(keys[1])
    t = np.array([pose.x(), pose.y()])
    a = rotation_matrix(-b) / (1.0 + k)
    d = t - origin
    error = origin + a @ d - measured
    if jacobians is not None:
        h_pose = np.zeros((2, 3))
        h_pose[:, :2] = a @ rotation_matrix(pose.theta())  # GTSAM moves a Pose2's position by R(theta) dt
        jacobians[0] = h_pose
        jacobians[1] = np.column_stack([-(a @ d) / (1.0 + k), -(a @ _J @ d)])
    return error


def world_position_factor(pose_key: int, position, cov, origin, kernel: str = "none",
                          parameter: float = 1.0) -> gtsam.CustomFactor:
    """A factor on a DR-frame pose and the calibration: the pose's world position is ``position``
    with covariance ``cov (2, 2)`` (world frame), optionally under a robust kernel."""
    measured = np.asarray(position, float).copy()
    noise = robust_noise(np.asarray(cov, float), kernel, parameter)
    return gtsam.CustomFactor(noise, [int(pose_key), CALIBRATION],
                              partial(_position_error, np.asarray(origin, float).copy(), measured))


def _position_tide_error(origin, measured, factor, values, jacobians):
    """Error ``(world position, tide) - measured`` of a pose (key 0) under the calibration
    (key 1), with the tide (key 2)."""
    inner = [None, None] if jacobians is not None else None
    error = _position_error(origin, measured[:2], factor, values, inner)
    tide = float(values.atVector(factor.keys()[2])[0])
    if jacobians is not None:
        jacobians[0] = np.vstack([inner[0], np.zeros((1, 3))])
        jacobians[1] = np.vstack([inner[1], np.zeros((1, 2))])
        jacobians[2] = np.array([[0.0], [0.0], [1.0]])
    return np.append(error, tide - measured[2])


def position_tide_factor(pose_key: int, measured, cov, origin, kernel: str = "none",
                         parameter: float = 1.0, tide_key: int = TIDE) -> gtsam.CustomFactor:
    """A factor on a DR-frame pose, the calibration and the tide (``tide_key``): the pose's world
    position and the tide are ``measured (3,)`` with covariance ``cov (3, 3)``, optionally under
    a robust kernel whose ``parameter`` is given for a 2-D error (it is moved to the same
    probability of a 3-D one)."""
    from scipy import stats

    measured = np.asarray(measured, float).copy()
    if kernel != "none":
        parameter = float(np.sqrt(stats.chi2.ppf(stats.chi2.cdf(parameter**2, 2), 3)))
    noise = robust_noise(np.asarray(cov, float), kernel, parameter)
    return gtsam.CustomFactor(noise, [int(pose_key), CALIBRATION, int(tide_key)],
                              partial(_position_tide_error, np.asarray(origin, float).copy(), measured))


def calibration_prior_factor(mean, std) -> gtsam.NonlinearFactor:
    """The Gaussian prior of ``c = (k, b)``."""
    return gtsam.PriorFactorVector(CALIBRATION, np.asarray(mean, float),
                                   gtsam.noiseModel.Diagonal.Sigmas(np.asarray(std, float)))


def calibration_summary(calibration, joint, pose, dr_heading: float) -> dict:
    """The calibration as a track reports it: ``speed_scale`` and ``heading_bias`` (the constant
    errors) with their stds, and ``heading_error`` (DR minus true heading at ``pose``: the bias
    plus the heading walk so far) with its std; ``joint (5, 5)`` is the covariance of the
    DR-frame ``pose`` and the calibration."""
    joint = np.asarray(joint, float)
    error = float(wrap_angle(dr_heading - (pose[2] - calibration[1])))
    grad = np.array([0.0, 0.0, -1.0, 0.0, 1.0])
    return {
        "speed_scale": float(calibration[0]),
        "speed_scale_std": float(np.sqrt(max(joint[3, 3], 0.0))),
        "heading_bias": float(calibration[1]),
        "heading_bias_std": float(np.sqrt(max(joint[4, 4], 0.0))),
        "heading_error": error,
        "heading_error_std": float(np.sqrt(max(grad @ joint @ grad, 0.0))),
    }
