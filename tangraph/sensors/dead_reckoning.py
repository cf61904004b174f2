"""Dead reckoning: an INS/DVL error model, its simulation, odometry increments and their covariance.

Positions are ``(north, east)`` in metres, heading ``psi`` in radians clockwise from north, the
body frame is x forward, y starboard; a pose is ``(north, east, psi)``. ``R(psi)`` below turns
a body vector ``(forward, starboard)`` into ``(north, east)``.

The DR heading is the true heading plus an error ``bias + walk + white``. The walk grows with
time and, where the heading error depends on the heading itself (a magnetic compass's
deviation, the crab angle a current gives a DR that runs along the heading), with the angle
turned: :func:`walk_variance`. Over each interval
``[t_k, t_k+1)`` the true body-frame velocity (from the true pose difference, so sideslip is
kept) is measured by the DVL with a scale factor and white noise, or, while the DVL has lost
bottom lock, by the INS alone with a velocity error that walks from zero since the dropout
began; the DR position integrates it with the DR heading of ``t_k``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.errors import TangraphError
from tangraph.geometry import between, rotate, rotation_matrix, wrap_angle  # rotation_matrix: re-exported
from tangraph.validation import check_number

__all__ = [
    "DeadReckoning",
    "DeadReckoningModel",
    "increment_covariance",
    "odometry",
    "rotation_matrix",
    "simulate_dead_reckoning",
    "walk_variance",
]


@dataclasses.dataclass(frozen=True)
class DeadReckoningModel:
    """Errors of an INS/DVL dead-reckoning solution.

    Parameters
    ----------
    heading_bias : float
        Constant heading error, rad.
    heading_walk : float
        Random walk of the heading error, rad/sqrt(s): its variance grows by
        ``heading_walk**2`` per second (from zero at the start).
    heading_turn_std : float
        Std of the heading error's change over a turn of 180 deg, rad: a heading error that
        depends on the heading (a magnetic compass's deviation, ``A sin(psi + phi)``, gives
        ``sqrt(2) A``; so does the crab angle of a current for a DR that runs along the heading)
        walks with the angle turned, its variance growing by ``heading_turn_std**2 / pi`` per
        radian (:func:`walk_variance`). 0: the heading error does not depend on the heading.
    heading_deviation, heading_deviation_phase : float
        A magnetic compass's deviation, rad: the heading error gains ``heading_deviation *
        sin(psi + heading_deviation_phase)`` at the true heading ``psi`` (hard iron: a
        semicircular deviation curve, the same at every return to a heading). The estimators do
        not know the curve; they model it as a walk with the angle turned of
        ``heading_turn_std = sqrt(2) heading_deviation``
        (:meth:`~tangraph.sensors.NavigationModel.from_dead_reckoning`).
    heading_noise : float
        White heading error of each sample, rad (std).
    speed_scale : float
        Constant fractional scale-factor error of the DVL velocity (0.01: 1 % too fast).
    speed_noise : float
        White DVL velocity error, m/s (std), independent on the forward and starboard axes
        and between intervals.
    dropout_rate : float
        DVL bottom-lock dropouts per hour (Poisson starts).
    dropout_duration : float
        Mean length of a dropout, s (exponential).
    dropout_speed_noise : float
        INS-only velocity error while the DVL is out: a random walk in the (north, east)
        velocity, m/s/sqrt(s), starting at zero when the dropout starts.
    start_position_std : float
        Error of the start position the DR is initialised with, m (std per axis): the simulated
        DR starts this far (drawn) from the true start.

    Examples
    --------
    >>> DeadReckoningModel.chen2022().speed_noise
    0.1
    >>> DeadReckoningModel(speed_noise=-1.0)
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: DeadReckoningModel.speed_noise must be >= 0, got -1.0
    """

    heading_bias: float = 0.0
    heading_walk: float = 0.0
    heading_noise: float = 0.0
    speed_scale: float = 0.0
    speed_noise: float = 0.0
    heading_turn_std: float = 0.0
    dropout_rate: float = 0.0
    dropout_duration: float = 0.0
    dropout_speed_noise: float = 0.0
    start_position_std: float = 0.0
    heading_deviation: float = 0.0
    heading_deviation_phase: float = 0.0

    def __post_init__(self) -> None:
        check_number(self, "heading_bias", low=None)
        check_number(self, "heading_deviation_phase", low=None)
        check_number(self, "speed_scale", low=-1.0, open_low=True)
        for name in ("heading_walk", "heading_turn_std", "heading_deviation", "heading_noise", "speed_noise",
                     "dropout_rate", "dropout_duration", "dropout_speed_noise", "start_position_std"):
            check_number(self, name)
        if self.dropout_rate > 0 and self.dropout_duration <= 0:
            raise TangraphError(
                f"DeadReckoningModel.dropout_duration must be > 0 when dropout_rate > 0, "
                f"got {self.dropout_duration!r}"
            )

    @classmethod
    def chen2022(cls) -> DeadReckoningModel:
        """Chen & Che (2022), Table 1: "heading error 2 deg, speed error 0.1 m/s".

        The paper does not say what kind of errors these are; they are read here as a constant
        heading bias of 2 deg and a white speed noise of std 0.1 m/s (nothing else).
        """
        return cls(heading_bias=float(np.deg2rad(2.0)), speed_noise=0.1)

    @classmethod
    def ideal(cls) -> DeadReckoningModel:
        """No error at all: dead reckoning reproduces the true track."""
        return cls()


@dataclasses.dataclass(frozen=True, eq=False)
class DeadReckoning:
    """A simulated dead-reckoning run: ``pose (K, 3)``, ``heading_error (K,)`` (DR minus true,
    rad), ``dvl_valid (K,)`` (bottom lock over the interval starting at each sample) and
    ``n_dropouts`` (dropouts drawn, including any that fell between samples)."""

    pose: np.ndarray
    heading_error: np.ndarray
    dvl_valid: np.ndarray
    n_dropouts: int

    def __post_init__(self) -> None:
        pose = np.array(self.pose, dtype=np.float64)
        k = pose.shape[0] if pose.ndim == 2 else -1
        err = np.array(self.heading_error, dtype=np.float64)
        valid = np.array(self.dvl_valid, dtype=bool)
        if pose.shape != (k, 3) or err.shape != (k,) or valid.shape != (k,):
            raise TangraphError(
                f"DeadReckoning: pose {pose.shape}, heading_error {err.shape} and dvl_valid "
                f"{valid.shape} must be (K, 3), (K,), (K,)"
            )
        for name, a in (("pose", pose), ("heading_error", err), ("dvl_valid", valid)):
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        object.__setattr__(self, "n_dropouts", int(self.n_dropouts))


def walk_variance(heading_walk: float, heading_turn_std: float, dt, turn):
    """Variance (rad^2) the heading error's walk gains over intervals of ``dt`` (s) in which the
    heading turns by ``turn`` (rad, either sign): ``heading_walk**2 dt + heading_turn_std**2
    |turn| / pi``. The one place every estimator, the bound and the simulator take it from.

    Examples
    --------
    >>> float(walk_variance(0.0, 0.1, 10.0, -np.pi))  # a U-turn: the turn std's square
    0.010000000000000002
    """
    variance = heading_walk**2 * np.asarray(dt, dtype=np.float64)
    if heading_turn_std > 0:
        variance = variance + heading_turn_std**2 / np.pi * np.abs(np.asarray(turn, dtype=np.float64))
    return variance


def _check_track(time, pose, pose_name: str) -> tuple[np.ndarray, np.ndarray]:
    t = np.asarray(time, dtype=np.float64)
    p = np.asarray(pose, dtype=np.float64)
    if t.ndim != 1 or t.size < 1 or p.shape != (t.size, 3):
        raise TangraphError(f"time must be (K,) and {pose_name} (K, 3), got {t.shape} and {p.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(p))):
        raise TangraphError(f"time and {pose_name} must be finite")
    if np.any(np.diff(t) <= 0):
        raise TangraphError("time must be strictly increasing")
    return t, p


def _dropouts(t: np.ndarray, model: DeadReckoningModel, rng) -> tuple[np.ndarray, int]:
    """DVL validity at each sample and the number of dropouts (Poisson starts, exp. lengths)."""
    span = t[-1] - t[0]
    n = int(rng.poisson(model.dropout_rate / 3600.0 * span))
    start = t[0] + span * rng.random(n)
    end = start + rng.exponential(model.dropout_duration, n)
    count = np.zeros(t.size + 1, dtype=np.int64)
    np.add.at(count, np.searchsorted(t, start, "left"), 1)
    np.add.at(count, np.searchsorted(t, end, "left"), -1)
    return np.cumsum(count[:-1]) == 0, n


def _run_onset(valid: np.ndarray) -> np.ndarray:
    """Index of the first interval of the dropout containing each interval (k+1 if valid)."""
    idx = np.arange(valid.size)
    return np.maximum.accumulate(np.where(valid, idx, -1)) + 1


def simulate_dead_reckoning(time, true_pose, model: DeadReckoningModel, *,
                            rng: np.random.Generator, start_pose=None) -> DeadReckoning:
    """Dead-reckon a true track with the errors of ``model``.

    Parameters
    ----------
    time : array_like, shape (K,)
        Strictly increasing sample times, s.
    true_pose : array_like, shape (K, 3)
        True ``(north, east, psi)`` at those times.
    model : DeadReckoningModel
    rng : numpy.random.Generator
        The same draws are made whatever the model, so runs with the same seed share noise.
    start_pose : array_like, shape (3,), optional
        Where the DR believes it starts; by default the true start pose moved by a draw of
        ``model.start_position_std`` on each axis (from a child of ``rng``, so the other draws
        stay those of the same seed). Its heading offset from the truth is kept as a constant
        heading error (an INS alignment error).

    Returns
    -------
    DeadReckoning
        The DR position starts exactly at the start pose; the DR heading at every sample is the
        true heading plus ``heading_error`` (not wrapped, on the branch of ``true_pose``).

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(11.0)
    >>> truth = np.column_stack([t, 0 * t, 0 * t])  # 1 m/s due north
    >>> dr = simulate_dead_reckoning(t, truth, DeadReckoningModel(speed_scale=0.01),
    ...                              rng=np.random.default_rng(0))
    >>> dr.pose[-1].round(6).tolist()
    [10.1, 0.0, 0.0]
    """
    t, pose = _check_track(time, true_pose, "true_pose")
    if start_pose is not None:
        start = np.asarray(start_pose, dtype=np.float64)
    elif model.start_position_std > 0:
        offset = model.start_position_std * rng.spawn(1)[0].standard_normal(2)
        start = pose[0] + np.array([offset[0], offset[1], 0.0])
    else:
        start = pose[0]
    if start.shape != (3,) or not np.all(np.isfinite(start)):
        raise TangraphError(f"start_pose must be 3 finite numbers, got {start_pose!r}")
    k = t.size
    dt = np.diff(t)
    valid, n_dropouts = _dropouts(t, model, rng)
    if model.heading_turn_std > 0:
        turned = wrap_angle(np.diff(pose[:, 2]))
        step_std = np.sqrt(walk_variance(model.heading_walk, model.heading_turn_std, dt, turned))
    else:
        step_std = model.heading_walk * np.sqrt(dt)
    walk = np.concatenate([[0.0], np.cumsum(step_std * rng.standard_normal(k - 1))])
    heading_error = (model.heading_bias + wrap_angle(start[2] - pose[0, 2]) + walk
                     + model.heading_noise * rng.standard_normal(k))
    if model.heading_deviation > 0:  # the curve at the true heading: no draw
        deviation = model.heading_deviation * np.sin(pose[:, 2] + model.heading_deviation_phase)
        heading_error = heading_error + deviation
    body = rotate(-pose[:-1, 2], np.diff(pose[:, :2], axis=0))  # true (forward, starboard) steps
    lock = valid[:-1, None]
    dvl = (1.0 + model.speed_scale) * body + model.speed_noise * dt[:, None] * rng.standard_normal((k - 1, 2))
    psi = pose[:, 2] + heading_error
    step = rotate(psi[:-1], np.where(lock, dvl, body))
    # INS velocity error: a (north, east) random walk restarted at each dropout's first interval.
    kick = model.dropout_speed_noise * np.sqrt(dt)[:, None] * rng.standard_normal((k - 1, 2))
    kick = np.where(lock, 0.0, kick)
    total = np.concatenate([np.zeros((1, 2)), np.cumsum(kick, axis=0)])
    ins = np.where(lock, 0.0, total[:-1] - total[_run_onset(valid[:-1])])
    step = step + ins * dt[:, None]
    north_east = start[:2] + np.concatenate([np.zeros((1, 2)), np.cumsum(step, axis=0)])
    return DeadReckoning(np.column_stack([north_east, psi]), heading_error, valid, n_dropouts)


def _check_pairs(i, j, k: int) -> tuple[np.ndarray, np.ndarray]:
    ii, jj = np.asarray(i), np.asarray(j)
    for name, a in (("i", ii), ("j", jj)):
        if not np.issubdtype(a.dtype, np.integer):
            raise TangraphError(f"{name} must hold integer pose indices, got dtype {a.dtype}")
        if a.size and (a.min() < 0 or a.max() >= k):
            raise TangraphError(f"{name} indexes poses {a.min()}..{a.max()}, but there are {k}")
    try:
        return tuple(a.astype(np.int64) for a in np.broadcast_arrays(ii, jj))  # type: ignore[return-value]
    except ValueError:
        raise TangraphError(f"i {ii.shape} and j {jj.shape} do not broadcast") from None


def odometry(dr_pose, i, j) -> np.ndarray:
    """The SE(2) increment from pose ``i`` to pose ``j``, in the frame of pose ``i``.

    Returns ``(..., 3)`` = ``(forward, starboard, dpsi)`` with the broadcast shape of ``i``
    and ``j``; ``dpsi`` is wrapped to ``[-pi, pi)``. Composing it onto pose ``i`` gives pose ``j``.

    Examples
    --------
    >>> import numpy as np
    >>> poses = np.array([[0.0, 0.0, np.pi / 2], [0.0, 10.0, np.pi / 2], [-5.0, 10.0, np.pi]])
    >>> odometry(poses, [0, 0], [1, 2]).round(6).tolist()
    [[10.0, 0.0, 0.0], [10.0, 5.0, 1.570796]]
    """
    pose = np.asarray(dr_pose, dtype=np.float64)
    if pose.ndim != 2 or pose.shape[1] != 3:
        raise TangraphError(f"dr_pose must have shape (K, 3), got {pose.shape}")
    ii, jj = _check_pairs(i, j, pose.shape[0])
    return between(pose[ii], pose[jj])


def increment_covariance(model: DeadReckoningModel, time, dr_pose, i, j, *, dvl_valid=None,
                         include_bias: bool = False) -> np.ndarray:
    """Covariance ``(..., 3, 3)`` of :func:`odometry` increments, by first-order propagation.

    Parameters
    ----------
    model : DeadReckoningModel
    time : array_like, shape (K,)
    dr_pose : array_like, shape (K, 3)
        The DR poses (the linearisation point).
    i, j : array_like of int
        Index pairs with ``i <= j`` (broadcast).
    dvl_valid : array_like of bool, shape (K,), optional
        Bottom lock per interval (``DeadReckoning.dvl_valid``); by default always valid.
    include_bias : bool
        Add the constant errors as if they were random (see Notes).

    Notes
    -----
    Terms: white DVL noise, ``speed_noise**2 * sum(dt**2)`` on each axis (lock intervals);
    the INS velocity walk over dropouts (with the part accumulated before ``i``); the heading
    walk (:func:`walk_variance`, its turn part from the headings of ``dr_pose``) and white
    heading noise *relative to pose i*, each rotating the later steps.
    A constant heading bias rotates all DR poses alike, so it cancels exactly in an increment
    in the frame of DR pose ``i``; the speed scale is constant too. Neither is random within
    a run. ``include_bias=True`` adds them as variances anyway, ``heading_bias**2 * d**2``
    across and ``speed_scale**2 * d**2`` along the increment's chord ``d``, for increments
    composed on an unbiased heading.

    Examples
    --------
    >>> import numpy as np
    >>> t = np.arange(11.0)
    >>> poses = np.column_stack([t, 0 * t, 0 * t])
    >>> cov = increment_covariance(DeadReckoningModel(speed_noise=0.1), t, poses, 0, 10)
    >>> np.diag(cov).round(6).tolist()
    [0.1, 0.1, 0.0]
    """
    t, pose = _check_track(time, dr_pose, "dr_pose")
    ii, jj = _check_pairs(i, j, t.size)
    if np.any(jj < ii):
        raise TangraphError("increment_covariance needs i <= j for every pair")
    valid = np.ones(t.size, bool) if dvl_valid is None else np.asarray(dvl_valid, dtype=bool)
    if valid.shape != t.shape:
        raise TangraphError(f"dvl_valid must have shape {t.shape}, got {valid.shape}")
    shape = ii.shape
    ii, jj = ii.ravel(), jj.ravel()
    cov = np.zeros((ii.size, 3, 3))
    if t.size > 1:
        lock = valid[:-1]
        # The window of intervals k = i + p, p < j - i, padded to the longest pair.
        p = np.arange(max(int(np.max(jj - ii, initial=0)), 1))
        inside = p < (jj - ii)[:, None]
        k = np.minimum(ii[:, None] + p, t.size - 2)
        dtw = np.where(inside, np.diff(t)[k], 0.0)
        cov[:, :2, :2] = np.eye(2) * (
            model.speed_noise**2 * np.sum(np.where(lock[k], dtw**2, 0.0), axis=1)
            + model.dropout_speed_noise**2 * _ins_walk(t, lock, ii, jj, k, inside)
        )[:, None, None]
        cov += _heading_terms(model, pose, ii, jj, k, inside & (p > 0), dtw)
        to_i = rotation_matrix(-pose[ii, 2])  # world -> frame of pose i
        cov[:, :2, :2] = to_i @ cov[:, :2, :2] @ np.swapaxes(to_i, 1, 2)
        cov[:, :2, 2] = np.einsum("nab,nb->na", to_i, cov[:, :2, 2])
        cov[:, 2, :2] = cov[:, :2, 2]
    if include_bias:
        d = odometry(pose, ii, jj)[:, :2]
        across = np.column_stack([-d[:, 1], d[:, 0]])
        cov[:, :2, :2] += model.heading_bias**2 * across[:, :, None] * across[:, None, :]
        cov[:, :2, :2] += model.speed_scale**2 * d[:, :, None] * d[:, None, :]
    return cov.reshape(*shape, 3, 3)


def _heading_terms(model, pose, ii, jj, k, later, dtw) -> np.ndarray:
    """World-frame covariance from the heading walk and white heading noise relative to pose i."""
    step = np.diff(pose[:, :2], axis=0)
    c = np.where(later[..., None], np.column_stack([-step[:, 1], step[:, 0]])[k], 0.0)  # d step/d psi
    tail = np.cumsum(c[:, ::-1], axis=1)[:, ::-1]  # sum over p' >= p
    after = np.concatenate([tail[:, 1:], np.zeros_like(tail[:, :1])], axis=1)  # p' > p
    s2 = model.heading_noise**2
    turned = wrap_angle(np.diff(pose[:, 2]))[k] if model.heading_turn_std > 0 else 0.0
    q = np.where(dtw > 0, walk_variance(model.heading_walk, model.heading_turn_std, dtw, turned), 0.0)
    cov = np.zeros((ii.size, 3, 3))
    # A walk step in interval m turns every later step of the window (and psi_j).
    cov[:, :2, :2] = np.einsum("np,npa,npb->nab", q, after, after)
    cov[:, :2, 2] = np.einsum("np,npa->na", q, after)
    cov[:, 2, 2] = np.sum(q, axis=1)
    # White noise at each later sample turns its own step; that of pose i turns them all back.
    total = tail[:, 0]
    cov[:, :2, :2] += s2 * (np.einsum("npa,npb->nab", c, c) + total[:, :, None] * total[:, None, :])
    cov[:, :2, 2] += s2 * total
    cov[:, 2, 2] += 2 * s2 * (jj > ii)
    cov[:, 2, :2] = cov[:, :2, 2]
    return cov


def _ins_walk(t, lock, ii, jj, k, inside) -> np.ndarray:
    """Variance, per unit ``dropout_speed_noise**2``, of each axis of the INS position error."""
    n_int = lock.size
    onset = _run_onset(lock)
    # The first lock interval at or after each interval (n_int if none): its dropout's end.
    stop = np.minimum.accumulate(np.where(lock, np.arange(n_int), n_int)[::-1])[::-1]
    # A kick in interval m moves the velocity of the later intervals of its dropout in [i, j).
    reach = t[np.minimum(jj[:, None], stop[k])] - t[k + 1]
    total = np.sum(np.where(inside & ~lock[k], np.diff(t)[k] * reach**2, 0.0), axis=1)
    # Kicks before i, in the dropout holding interval i, move all its intervals in [i, j).
    first = np.minimum(ii, n_int - 1)
    held = t[np.minimum(jj, stop[first])] - t[ii]
    carried = np.where(~lock[first] & (jj > ii), (t[first] - t[onset[first]]) * held**2, 0.0)
    return total + carried
