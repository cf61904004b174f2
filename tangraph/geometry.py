"""Plane geometry of tangraph's poses, written once: rotations, angle wrapping, SE(2) composition,
the DR calibration's similarity, the Mahalanobis distance and its gates.

The conventions are those of :doc:`/conventions`: positions are ``(north, east)`` in metres, a
heading ``psi`` is in radians clockwise from north, a pose is ``(north, east, psi)`` and a body
vector ``(forward, starboard)``; ``R(psi)`` turns a body vector into ``(north, east)``. Every
function takes arrays and works over their leading axes (broadcast where it says so).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "between",
    "body_to_world",
    "compose",
    "from_dr_frame",
    "gate_threshold",
    "is_precise",
    "mahalanobis2",
    "rotate",
    "rotation_matrix",
    "to_dr_frame",
    "world_to_body",
    "wrap_angle",
    "wrap_near",
]


def wrap_angle(angle):
    """Angles wrapped to ``[-pi, pi)``: ``(angle + pi) mod 2 pi - pi`` (so ``pi`` becomes ``-pi``).

    Examples
    --------
    >>> import numpy as np
    >>> np.degrees(wrap_angle(np.radians([90.0, 270.0, 180.0, -180.0, 540.0]))).round(6).tolist()
    [90.0, -90.0, -180.0, -180.0, -180.0]
    """
    return (angle + np.pi) % (2 * np.pi) - np.pi


def wrap_near(angle, reference):
    """Angles moved by whole turns onto the branch of ``reference``:
    ``reference + wrap_angle(angle - reference)``, within ``[-pi, pi)`` of it (broadcast).

    Examples
    --------
    >>> import numpy as np
    >>> round(float(wrap_near(0.1, 2 * np.pi)), 6)  # 0.1 on the branch of 2 pi
    6.383185
    """
    return reference + wrap_angle(angle - reference)


def rotation_matrix(psi) -> np.ndarray:
    """Matrices ``R(psi) (..., 2, 2)`` (a heading's, clockwise from north, on ``(north, east)``)
    for a heading or an array of them.

    Examples
    --------
    >>> import numpy as np
    >>> rotation_matrix(np.pi / 2).round(6).tolist()
    [[0.0, -1.0], [1.0, 0.0]]
    """
    psi = np.asarray(psi, float)
    c, s = np.cos(psi), np.sin(psi)
    out = np.empty((*psi.shape, 2, 2))  # filled in place: stacking costs tens of microseconds a call
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    return out


def rotate(psi, vec) -> np.ndarray:
    """``R(psi) vec`` for vectors ``vec (..., 2)`` and headings ``psi`` (broadcast against
    ``vec[..., 0]``); ``rotate(-psi, v)`` is the inverse, ``R(psi)^T v``.

    Examples
    --------
    >>> import numpy as np
    >>> rotate(np.pi / 2, [10.0, 2.0]).round(6).tolist()  # heading east: starboard is south
    [-2.0, 10.0]
    """
    vec = np.asarray(vec, float)
    c, s = np.cos(psi), np.sin(psi)
    return np.stack([c * vec[..., 0] - s * vec[..., 1], s * vec[..., 0] + c * vec[..., 1]], axis=-1)


def body_to_world(pose, points) -> np.ndarray:
    """World ``(north, east) (..., 2)`` of body points ``(forward, starboard) (..., 2)`` seen
    from poses ``(..., 3)``: ``p + R(psi) points`` (broadcast).

    Examples
    --------
    >>> body_to_world([100.0, 50.0, np.pi / 2], [[10.0, 0.0], [0.0, 5.0]]).round(6).tolist()
    [[100.0, 60.0], [95.0, 50.0]]
    """
    pose, points = np.asarray(pose, float), np.asarray(points, float)
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    north = pose[..., 0] + c * points[..., 0] - s * points[..., 1]
    east = pose[..., 1] + s * points[..., 0] + c * points[..., 1]
    return np.stack([north, east], axis=-1)


def world_to_body(pose, points) -> np.ndarray:
    """Inverse of :func:`body_to_world`: body ``(forward, starboard)`` of world points
    ``(north, east) (..., 2)``, ``R(psi)^T (points - p)``.

    Examples
    --------
    >>> world_to_body([100.0, 50.0, np.pi / 2], [90.0, 60.0]).round(6).tolist()
    [10.0, 10.0]
    """
    pose, points = np.asarray(pose, float), np.asarray(points, float)
    return rotate(-pose[..., 2], points - pose[..., :2])


def compose(pose, increment) -> np.ndarray:
    """``pose (+) increment`` for arrays ``(..., 3)``: the SE(2) composition of tangraph's poses,
    an increment ``(forward, starboard, dpsi)`` in the frame of ``pose`` (the heading not wrapped).

    Examples
    --------
    >>> import numpy as np
    >>> compose([0.0, 0.0, np.pi / 2], [10.0, 5.0, np.pi / 2]).round(6).tolist()
    [-5.0, 10.0, 3.141593]
    """
    pose, increment = np.asarray(pose, float), np.asarray(increment, float)
    position = body_to_world(pose, increment[..., :2])
    return np.concatenate([position, (pose[..., 2] + increment[..., 2])[..., None]], axis=-1)


def between(pose_a, pose_b) -> np.ndarray:
    """The SE(2) increment ``(forward, starboard, dpsi) (..., 3)`` from poses ``a`` to poses
    ``b``, in the frame of ``a``; ``dpsi`` is wrapped to ``[-pi, pi)``. :func:`compose` of ``a``
    and it gives ``b`` (its heading up to whole turns).

    Examples
    --------
    >>> import numpy as np
    >>> between([0.0, 0.0, np.pi / 2], [-5.0, 10.0, np.pi]).round(6).tolist()
    [10.0, 5.0, 1.570796]
    """
    pose_a, pose_b = np.asarray(pose_a, float), np.asarray(pose_b, float)
    delta = world_to_body(pose_a, pose_b[..., :2])
    return np.concatenate([delta, wrap_angle(pose_b[..., 2] - pose_a[..., 2])[..., None]], axis=-1)


def to_dr_frame(world, calibration, origin) -> np.ndarray:
    """The DR calibration's similarity: world positions ``(..., 2)`` or poses ``(..., 3)`` as the
    dead reckoning sees them.

    With ``calibration = (k, b)`` (the DVL reads ``1 + k`` times the true speed, the DR heading is
    the true one plus ``b``), about the DR's start ``origin (2,)``::

        p' = o + (1 + k) R(b) (p - o),     psi' = psi + b.

    Examples
    --------
    >>> import numpy as np
    >>> to_dr_frame([[10.0, 0.0, 0.0]], [0.5, np.pi / 2], [0.0, 0.0]).round(6).tolist()
    [[0.0, 15.0, 1.570796]]
    """
    k, b = float(calibration[0]), float(calibration[1])
    world, origin = np.asarray(world, float), np.asarray(origin, float)
    out = np.array(world)
    out[..., :2] = origin + (1.0 + k) * ((world[..., :2] - origin) @ rotation_matrix(b).T)
    if out.shape[-1] == 3:
        out[..., 2] = out[..., 2] + b
    return out


def from_dr_frame(dr, calibration, origin) -> np.ndarray:
    """Inverse of :func:`to_dr_frame`: world positions ``(..., 2)`` or poses ``(..., 3)`` of
    dead-reckoned ones under ``calibration = (k, b)``.

    The map back to the world::

        p = o + R(-b) (p' - o) / (1 + k),     psi = psi' - b.

    Examples
    --------
    >>> import numpy as np
    >>> from_dr_frame([[0.0, 15.0, np.pi / 2]], [0.5, np.pi / 2], [0.0, 0.0]).round(6).tolist()
    [[10.0, 0.0, 0.0]]
    """
    k, b = float(calibration[0]), float(calibration[1])
    dr, origin = np.asarray(dr, float), np.asarray(origin, float)
    out = np.empty_like(dr)
    out[..., :2] = origin + (dr[..., :2] - origin) @ rotation_matrix(-b).T / (1.0 + k)
    if out.shape[-1] == 3:
        out[..., 2] = dr[..., 2] - b
    return out


def mahalanobis2(error, cov) -> np.ndarray:
    """Squared Mahalanobis distance ``e^T C^-1 e`` of vectors ``error (..., n)`` under
    covariances ``cov (..., n, n)`` (broadcast; one ``(n, n)`` matrix is factorised once): the
    NEES of an estimation error, the NIS of an innovation. Shape ``error.shape[:-1]``.

    Examples
    --------
    >>> import numpy as np
    >>> mahalanobis2([2.0, 1.0], np.diag([4.0, 1.0])).round(6).tolist()
    2.0
    >>> mahalanobis2([[2.0, 0.0], [0.0, 3.0]], np.diag([4.0, 1.0])).round(6).tolist()
    [1.0, 9.0]
    """
    e, c = np.asarray(error, float), np.asarray(cov, float)
    if c.ndim == 2:
        x = np.linalg.solve(c, e.reshape(-1, e.shape[-1]).T).T.reshape(e.shape)
    else:
        x = np.linalg.solve(c, e[..., None])[..., 0]
    return np.einsum("...i,...i->...", e, x)


def gate_threshold(probability: float | None, dof: int = 2) -> float:
    """The ``chi2(dof)`` quantile of a gate on a squared Mahalanobis distance (in the plane by
    default: ``-2 log(1 - p)``, exact for two degrees of freedom); inf without a gate (None).

    Examples
    --------
    >>> round(gate_threshold(0.999), 3), gate_threshold(None), round(gate_threshold(0.999, 3), 3)
    (13.816, inf, 16.266)
    """
    if probability is None:
        return math.inf
    if dof == 2:
        return float(-2.0 * math.log1p(-float(probability)))
    from scipy import stats  # only for a gate of other than two degrees of freedom

    return float(stats.chi2.ppf(float(probability), dof))


def is_precise(covariance, half_width: float, sigmas: float, share: float = 0.5) -> bool:
    """Whether a fix of covariance ``(2, 2)`` is precise for its search: its largest std within
    ``share / sigmas`` of the search's ``half_width`` (a search of ``sigmas`` times the
    prediction's std: within ``share`` of that std). Two vague fixes agree with anything, so only
    a precise one may confirm another or relocalise.

    Examples
    --------
    >>> is_precise(np.diag([4.0, 1.0]), 40.0, 4.0), is_precise(np.diag([36.0, 1.0]), 40.0, 4.0)
    (True, False)
    """
    largest = float(np.sqrt(np.linalg.eigvalsh(np.asarray(covariance, dtype=np.float64)).max()))
    return largest <= share * float(half_width) / float(sigmas)
