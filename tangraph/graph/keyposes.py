"""Key poses, the odometry between them, and :class:`PoseGraph`, the factors of one run.

Key poses are a subset of the pings (the pose graph does not hold every ping): the first and last
ping, every TAP window end, and a ping whenever ``key_interval`` seconds have passed since the
previous key. The odometry between consecutive keys is the DR increment
(:func:`tangraph.sensors.odometry`) with the covariance of the DR error model
(:func:`tangraph.sensors.increment_covariance`).
"""

from __future__ import annotations

import dataclasses
from typing import cast

import gtsam
import numpy as np

from tangraph.errors import TangraphError
from tangraph.graph.calibration import (
    CALIBRATION,
    calibration_prior_factor,
    world_position_factor,
)
from tangraph.graph.factors import between_noise, pose_prior_factor, position_fix_factor
from tangraph.sensors import DeadReckoningModel, increment_covariance, odometry

__all__ = ["PoseGraph", "fix_windows", "increments", "key_indices", "translate_error", "window_ends"]

_MAX_PAD = 2_000_000  # pairs x longest pair held at once by increment_covariance


def window_ends(n_pings: int, window: int, spacing: int) -> np.ndarray:
    """Last ping of every TAP window: ``window - 1``, then every ``spacing`` pings."""
    return np.arange(window - 1, n_pings, spacing, dtype=np.int64)


def fix_windows(n_pings: int, window: int, spacing: int, ramp: int | None = None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The TAP windows of a survey: ``first`` and ``end`` ping of each, and its ``overlap``.

    Full windows of ``window`` pings end at ``window - 1`` and then every ``spacing`` pings
    (:func:`window_ends`). With ``ramp`` (< ``window``), windows of ``ramp`` pings end every
    ``ramp`` pings before the first full one, so the first fix comes after ``ramp`` pings, not
    ``window``. A window's ``overlap`` is the mean, over its pings, of the number of windows
    that hold each ping: its TAP covariance, multiplied by it, counts every sounding's
    information once in all.

    Examples
    --------
    >>> first, end, overlap = fix_windows(40, 20, 10, ramp=5)
    >>> first.tolist(), end.tolist()
    ([0, 5, 10, 0, 10, 20], [4, 9, 14, 19, 29, 39])
    >>> overlap.round(2).tolist()
    [2.0, 2.0, 3.0, 2.25, 2.25, 1.5]
    """
    full = window_ends(n_pings, window, spacing)
    early = np.arange(ramp - 1, min(window - 1, n_pings), ramp, dtype=np.int64) if ramp and ramp < window \
        else np.zeros(0, np.int64)
    end = np.concatenate([early, full])
    first = np.concatenate([early - cast(int, ramp) + 1 if early.size else early, full - window + 1])
    count = np.zeros(n_pings + 1)
    np.add.at(count, first, 1.0)
    np.add.at(count, end + 1, -1.0)
    held = np.cumsum(count)[:n_pings]
    total = np.concatenate([[0.0], np.cumsum(held)])
    overlap = (total[end + 1] - total[first]) / (end - first + 1)
    return first, end, np.maximum(overlap, 1.0)


def key_indices(time, fix_ends, key_interval: float) -> np.ndarray:
    """Pings that are key poses: the first and last, every fix window end, and one whenever
    ``key_interval`` seconds have passed since the previous key."""
    time = np.asarray(time, float)
    is_end = np.zeros(time.size, bool)
    is_end[np.asarray(fix_ends, np.int64)] = True
    is_end[[0, -1]] = True
    keys = [0]
    last = time[0]
    for k in range(1, time.size):
        if is_end[k] or time[k] - last >= key_interval:
            keys.append(k)
            last = time[k]
    return np.asarray(keys, np.int64)


def increments(model: DeadReckoningModel, time, dr_pose, i, j) -> tuple[np.ndarray, np.ndarray]:
    """DR increments ``(n, 3)`` from ping ``i`` to ping ``j`` and their covariances ``(n, 3, 3)``
    (frame of ping ``i``), in chunks so that long gaps do not need a huge padded array.

    ``model`` is the white part of the DR error model
    (:attr:`~tangraph.sensors.NavigationModel.dead_reckoning`): the constant errors are the
    calibration variable's, not noise (see :mod:`tangraph.graph.calibration`).
    """
    i, j = np.asarray(i, np.int64).ravel(), np.asarray(j, np.int64).ravel()
    delta = odometry(dr_pose, i, j) if i.size else np.zeros((0, 3))
    cov = np.zeros((i.size, 3, 3))
    start = 0
    while start < i.size:
        stop = start + 1
        longest = max(int(j[start] - i[start]), 1)
        while stop < i.size and (stop - start + 1) * max(longest, int(j[stop] - i[stop]), 1) <= _MAX_PAD:
            longest = max(longest, int(j[stop] - i[stop]))
            stop += 1
        cov[start:stop] = increment_covariance(model, time, dr_pose, i[start:stop], j[start:stop])
        start = stop
    return delta, cov


@dataclasses.dataclass
class PoseGraph:
    """The key poses and factors of one run, keyed by ping index (the GTSAM key is the ping index).

    A plain container: :class:`~tangraph.graph.GraphNavigator` fills it while it runs, the batch
    smoother (:func:`~tangraph.graph.smooth_pose_graph`) solves all of it at once.

    With ``calibration_std`` (the prior std of ``(k, b)``, see :mod:`tangraph.graph.calibration`)
    the key poses are in the DR frame about ``origin`` and the graph holds the calibration
    variable: position fixes and :meth:`add_start` measure world positions through it. Without
    it (None) poses are world poses and a fix is a plain translation prior.

    ``breaks`` maps a key to the extra position std (m) of the odometry into it: where an online
    navigator that found itself lost widened its belief (see ``GraphConfig.online.lost_windows``);
    ``start`` is the start's position prior ``(key, pose, covariance)`` (:meth:`add_start`), which
    a robust batch solve may find wrong; ``start_break`` the extra position std (m) a lost
    navigator gave it (:meth:`widen_start`).
    """

    calibration_std: np.ndarray | None = None
    calibration_mean: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(2))
    origin: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros(2))
    robust_kernel: str = "huber"
    robust_parameter: float = 2.45
    min_std: float = 0.01
    min_heading_std: float = 1e-4
    keys: list[int] = dataclasses.field(default_factory=list)
    times: list[float] = dataclasses.field(default_factory=list)
    initial: list[np.ndarray] = dataclasses.field(default_factory=list)
    odometry: list[tuple[int, int, np.ndarray, np.ndarray]] = dataclasses.field(default_factory=list)
    pose_priors: list[tuple[int, np.ndarray, np.ndarray]] = dataclasses.field(default_factory=list)
    fixes: list[tuple[int, np.ndarray, np.ndarray]] = dataclasses.field(default_factory=list)
    breaks: dict[int, float] = dataclasses.field(default_factory=dict)
    start: tuple[int, np.ndarray, np.ndarray] | None = None
    start_break: float = 0.0
    _factors: dict = dataclasses.field(
        default_factory=lambda: {"prior": [], "start": [], "odometry": [], "fix": []}, repr=False)

    def __post_init__(self) -> None:
        self.origin = np.asarray(self.origin, float).copy()
        self.calibration_mean = np.asarray(self.calibration_mean, float).copy()
        if self.calibration_std is not None:
            self.calibration_std = np.asarray(self.calibration_std, float).copy()
            if not self._factors["prior"]:
                self._factors["prior"].append(
                    calibration_prior_factor(self.calibration_mean, self.calibration_std))

    @property
    def calibrated(self) -> bool:
        """Whether the graph holds the calibration variable."""
        return self.calibration_std is not None

    def add_start(self, key: int, pose, position_std: float, heading_std: float) -> list:
        """The start: the world position of pose ``key`` is its DR position with std
        ``position_std`` (through the calibration), and its DR-frame heading the DR heading with
        std ``heading_std`` (the constant heading error is the calibration's). Returns the factors."""
        pose = np.asarray(pose, float)
        cov = np.diag([position_std**2, position_std**2, heading_std**2])
        self.start = (int(key), pose, cov)
        self.pose_priors.append(self.start)
        if not self.calibrated:
            factor = self.start_factor()
            self._factors["start"].append(factor)
            return [factor]
        heading = gtsam.PriorFactorPose2(
            int(key), gtsam.Pose2(*pose),
            gtsam.noiseModel.Diagonal.Sigmas(np.array([1e4, 1e4, heading_std])))
        position = self.start_factor()
        self._factors["prior"].append(heading)
        self._factors["start"].append(position)
        return [heading, position]

    def start_factor(self, weight: float = 1.0) -> gtsam.NonlinearFactor:
        """The factor of the start's position (a pose prior without the calibration), widened
        by ``start_break``, its information multiplied by ``weight``."""
        assert self.start is not None, "start_factor before the start is set"
        key, pose, cov = self.start
        cov = cov + np.diag([self.start_break**2, self.start_break**2, 0.0])
        if not self.calibrated:
            return pose_prior_factor(key, pose, cov / weight)
        return world_position_factor(key, pose[:2], cov[:2, :2] / weight, self.origin)

    def widen_start(self, std: float) -> gtsam.NonlinearFactor:
        """Widen the start's position prior by ``std`` (m; a lost navigator's break when no fix
        was ever trusted) and return its new factor (which replaces the old one here)."""
        self.start_break = float(np.hypot(self.start_break, std))
        factor = self.start_factor()
        self._factors["start"] = [factor]
        return factor

    def add_pose(self, key: int, time: float, initial_pose) -> None:
        """A key pose at ping ``key`` with its initial estimate ``(north, east, psi)``."""
        if self.keys and key <= self.keys[-1]:
            raise TangraphError(
                f"key poses must be added in increasing ping order: {key} after {self.keys[-1]}"
            )
        self.keys.append(int(key))
        self.times.append(float(time))
        self.initial.append(np.asarray(initial_pose, float).copy())

    def add_pose_prior(self, key: int, pose, cov_world) -> gtsam.NonlinearFactor:
        """A prior on a whole pose (world-frame covariance); returns the GTSAM factor."""
        self.pose_priors.append((int(key), np.asarray(pose, float), np.asarray(cov_world, float)))
        factor = pose_prior_factor(key, pose, cov_world)
        self._factors["prior"].append(factor)
        return factor

    def add_odometry(self, i: int, j: int, increment, increment_cov, *, break_std: float = 0.0
                     ) -> gtsam.NonlinearFactor:
        """The DR increment from pose ``i`` to pose ``j`` with its covariance (frame of ``i``);
        ``break_std`` (m) widens its position part (a lost navigator's break, kept in ``breaks``)."""
        increment = np.asarray(increment, float)
        cov = between_noise(increment, increment_cov, self.min_std, self.min_heading_std)
        self.odometry.append((int(i), int(j), increment, cov))
        if break_std > 0:
            self.breaks[int(j)] = float(break_std)
        factor = self._odometry_factor(i, j, increment, cov, break_std)
        self._factors["odometry"].append(factor)
        return factor

    @staticmethod
    def _odometry_factor(i, j, increment, cov, break_std: float = 0.0) -> gtsam.NonlinearFactor:
        cov = cov + np.diag([break_std**2, break_std**2, 0.0])  # isotropic: the same in any frame
        return gtsam.BetweenFactorPose2(int(i), int(j), gtsam.Pose2(*increment),
                                        gtsam.noiseModel.Gaussian.Covariance(cov))

    def add_position_fix(self, key: int, position, cov, factor=None) -> gtsam.NonlinearFactor:
        """A position fix (a checked 2 x 2 world covariance) on pose ``key``, robust noise model;
        ``factor``: the one to add for it instead (the online graph's factor on the position
        and the tide, whose position part the fix is; a batch solve rebuilds from the fixes)."""
        self.fixes.append((int(key), np.asarray(position, float), np.asarray(cov, float)))
        factor = self.fix_factor(key, position, cov) if factor is None else factor
        self._factors["fix"].append(factor)
        return factor

    def fix_factor(self, key: int, position, cov, kernel: str | None = None) -> gtsam.NonlinearFactor:
        """The factor of a position fix on pose ``key`` (not added to the graph), under
        ``kernel`` (default the graph's ``robust_kernel``)."""
        kernel = self.robust_kernel if kernel is None else kernel
        if self.calibrated:
            return world_position_factor(key, position, cov, self.origin, kernel, self.robust_parameter)
        return position_fix_factor(key, position, cov, kernel, self.robust_parameter)

    def with_fixes(self, fixes, *, start: bool = True, breaks: bool = True) -> PoseGraph:
        """A copy with the position fixes replaced by ``fixes``, ``(key, position, covariance)``
        each; without the start's position prior (``start=False``), or with the odometry of the
        breaks and the start's prior restored to the DR's and the model's own (``breaks=False``)."""
        factors = {kind: list(fs) for kind, fs in self._factors.items()} | {"fix": []}
        priors = list(self.pose_priors)
        if not start and self.start is not None:
            factors["start"] = []
            priors = [p for p in priors if p is not self.start]
        kept = dict(self.breaks) if breaks else {}
        if not breaks and self.breaks:
            factors["odometry"] = [self._odometry_factor(*odo) for odo in self.odometry]
        graph = dataclasses.replace(
            self, keys=list(self.keys), times=list(self.times), initial=list(self.initial),
            odometry=list(self.odometry), pose_priors=priors, fixes=[], breaks=kept,
            start=self.start if start else None, start_break=self.start_break if breaks else 0.0,
            _factors=factors,
        )
        if start and self.start is not None and not breaks and self.start_break:
            graph._factors["start"] = [graph.start_factor()]
        for key, position, cov in fixes:
            graph.add_position_fix(key, position, cov)
        return graph

    def factor_graph(self, kinds=("prior", "start", "odometry", "fix")) -> gtsam.NonlinearFactorGraph:
        """Every factor (or those of ``kinds``), as one GTSAM graph."""
        graph = gtsam.NonlinearFactorGraph()
        for kind in kinds:
            for factor in self._factors[kind]:
                graph.add(factor)
        return graph

    def values(self, poses=None, calibration=None) -> gtsam.Values:
        """Initial values (or ``poses (n_keys, 3)``) of every key pose, and of the calibration
        (default its prior mean) when the graph holds it."""
        values = gtsam.Values()
        for key, pose in zip(self.keys, self.initial if poses is None else poses, strict=True):
            values.insert(key, gtsam.Pose2(*pose))
        if self.calibrated:
            values.insert(CALIBRATION, np.asarray(
                self.calibration_mean if calibration is None else calibration, float))
        return values

    def unconstrained(self) -> list[list[int]]:
        """Groups of key poses (pings) that nothing ties to the map or to the first pose: parts of
        the chain linked by odometry with neither a pose prior nor fixes on two different poses."""
        index = {k: n for n, k in enumerate(self.keys)}
        parent = list(range(len(self.keys)))

        def root(n: int) -> int:
            while parent[n] != n:
                parent[n] = parent[parent[n]]
                n = parent[n]
            return n

        for i, j, _, _ in self.odometry:
            a, b = root(index[i]), root(index[j])
            if a != b:
                parent[max(a, b)] = min(a, b)
        anchored: dict[int, int] = {}
        for key, _, _ in self.pose_priors:
            anchored[root(index[key])] = 2
        fixed: dict[int, set[int]] = {}
        for key, _, _ in self.fixes:
            fixed.setdefault(root(index[key]), set()).add(key)
        groups: dict[int, list[int]] = {}
        for n, k in enumerate(self.keys):
            r = root(n)
            if anchored.get(r, 0) < 2 and len(fixed.get(r, ())) < 2:
                groups.setdefault(r, []).append(k)
        return list(groups.values())

    def check_determined(self) -> None:
        """Raise a TangraphError naming the key poses that are not constrained."""
        groups = self.unconstrained()
        if groups:
            parts = "; ".join(_describe(g, self) for g in groups[:5])
            raise TangraphError(
                f"the pose graph is indeterminant: {sum(map(len, groups))} key poses are not tied by "
                f"odometry to a pose with a prior (nor fixed by two position fixes): {parts}"
                + (f"; and {len(groups) - 5} more groups" if len(groups) > 5 else "")
            )


def _describe(group: list[int], graph: PoseGraph) -> str:
    times = dict(zip(graph.keys, graph.times, strict=True))
    first, last = group[0], group[-1]
    where = f"ping {first}" if first == last else f"pings {first}..{last} ({len(group)} key poses)"
    return f"{where} at t = {times[first]:.1f}..{times[last]:.1f} s"


def translate_error(exc: Exception, graph: PoseGraph) -> Exception:
    """A TangraphError naming the unconstrained poses for GTSAM's indeterminant-system error."""
    text = str(exc)
    if "ndetermina" not in text:
        return exc
    try:
        graph.check_determined()
    except TangraphError as named:
        return named
    import re

    near = re.search(r"near variable\s+(\d+)", text)
    return TangraphError(f"the pose graph is indeterminant (ill-conditioned)"
                         f"{'' if near is None else ' near ' + _variable(int(near.group(1)))}")


def _variable(key: int) -> str:
    """What a GTSAM key of the graph is, in words: a key pose (its ping), the calibration, a tide."""
    if key < 1 << 56:  # key poses are keyed by their ping
        return f"key pose {key} (ping {key})"
    symbol = gtsam.Symbol(key)
    name = {"c": "the calibration", "t": "the tide", "o": "the map offset"}.get(chr(symbol.chr()), "variable")
    return f"{name} ({gtsam.DefaultKeyFormatter(key)})"
