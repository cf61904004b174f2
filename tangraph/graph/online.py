"""`GraphNavigator`: online terrain-aided navigation on a pose graph, solved by iSAM2.

Each ping is a step. At a key pose (see :func:`~tangraph.graph.keyposes.key_indices`) the step
adds the odometry factor from the previous key, and at a TAP window end it makes the fix: the
search is centred on the predicted position (the latest key estimate composed with the DR
increment) with a half-width from its covariance, the fix is gated against that prediction, and
an accepted one becomes a robust translation prior (the window's fix is made, weighed for the
graph and judged in :mod:`tangraph.graph.online_fixes`). iSAM2 is then updated with only these new
factors and values (the containers are emptied after each update), and the marginal covariance
of the latest key (jointly with the DR's calibration) only is read. iSAM2 runs inside GTSAM's
incremental fixed-lag smoother, which keeps the newest ``GraphConfig.online.isam_window`` key poses and
the calibration and marginalises the older poses, so the work per update stays bounded as the
mission grows: without it each new fix moves the whole past and the update time grows with the
chain. Between key poses the output is the latest key estimate composed with the DR increment, its
covariance grown by the increment's (while tracking on soundings, updated by those since the key).
What the navigator does with a fix beyond the gate (use it, hold it for confirmation, drop it),
and how it finds out that it is lost and relocalises, is decided by the pure fix policy
(:mod:`tangraph.graph.policy`); :mod:`tangraph.graph.lost` puts each window to it and executes
its actions on the graph and iSAM2.

With ``GraphConfig.online.front_end = "pmf"`` a window's factor comes from the point-mass front end
(:mod:`tangraph.graph.posterior_fix`) instead of TAP: its prior is the prediction jointly with
the tide, which the graph then holds as a variable beside the calibration, its windows share no
ping, and an ambiguous window is held and grown by the next pings. With
``GraphConfig.online.terrain = "soundings"`` the navigator tracks on every sounding once it has
found the vehicle (:mod:`tangraph.graph.online_terrain`), and with ``acquire = "pmf"`` a point-mass
filter finds it (:mod:`tangraph.graph.acquisition`).
"""

from __future__ import annotations

import time as _time

import gtsam
import numpy as np

from tangraph.errors import TangraphError
from tangraph.fix_records import FixRecord
from tangraph.geometry import to_dr_frame, wrap_near
from tangraph.graph import online_fixes, online_tide
from tangraph.graph.acquisition import Acquisition
from tangraph.graph.calibration import (
    CALIBRATION,
    TIDE,
    calibration_summary,
    graph_calibration_std,
    joint_in_frame,
    to_world,
    world_covariance,
)
from tangraph.graph.config import GraphConfig
from tangraph.graph.factors import compose, propagate_joint
from tangraph.graph.fixes import FixOutcome, LostEpisode, check_tide_drift, fix_drift
from tangraph.graph.keyposes import PoseGraph, fix_windows, increments, key_indices, translate_error
from tangraph.graph.lost import take_window
from tangraph.graph.online_terrain import OnlineTerrain
from tangraph.graph.policy import FixPolicy, PolicyState
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import TerrainFix
from tangraph.sensors import NavigationModel, survey_map_error, survey_navigation_model
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["GraphNavigator", "navigate_online"]


class GraphNavigator:
    """Online navigator: one :meth:`step` per ping, iSAM2 updated at key poses only.

    The key poses are in the DR frame and the graph holds the DR's calibration ``c = (k, b)``
    (:mod:`tangraph.graph.calibration`); every pose and covariance it reports is in the world
    frame, mapped with the current estimate of ``c`` and carrying its uncertainty. The
    calibration variable is never marginalised.

    Parameters
    ----------
    survey : Survey
    bathymetry : BathymetryMap
    config : GraphConfig, optional
    model : NavigationModel, optional
        What the navigator believes about the DR and the sonar; by default the one of a
        simulated survey (:meth:`NavigationModel.from_survey`).

    Examples
    --------
    >>> nav = GraphNavigator(survey, bathymetry)          # doctest: +SKIP
    >>> for k in range(survey.n_pings):                   # doctest: +SKIP
    ...     pose, cov = nav.step()
    >>> track = nav.track()                               # doctest: +SKIP
    """

    datum_key: int | None  #: the datum of a drifting tide (:mod:`tangraph.graph.online_tide`)

    def __init__(self, survey: Survey, bathymetry: BathymetryMap, config: GraphConfig | None = None, *,
                 model: NavigationModel | None = None) -> None:
        self.survey = survey
        self.bathymetry = bathymetry
        self.config = config or GraphConfig()
        if not isinstance(self.config, GraphConfig):
            raise TangraphError(f"config must be a GraphConfig, got {type(self.config).__name__}")
        self.model = check_tide_drift(self.config, survey_navigation_model(survey, model, where="graph",
                                                                           bathymetry=bathymetry))
        self.white = self.model.dead_reckoning
        self.fix_drift = fix_drift(self.model, self.config, survey.time)  # what widens each fix's window
        # (the map error each sounding shares with the survey's others: it widens every fix)
        self.shared_map_variance, self.map_error = survey_map_error(survey, bathymetry, self.model)
        c = self.config
        n = survey.n_pings
        self.origin = np.asarray(survey.dr_pose[0, :2], float).copy()
        # the point-mass front end's windows share no ping (window = spacing, no ramp)
        ramp = c.fixes.ramp_pings if c.online.front_end == "tap" else None
        firsts, self.fix_ends, overlaps = fix_windows(n, c.window, c.spacing, ramp)
        self.window_first = dict(zip(self.fix_ends.tolist(), firsts.tolist(), strict=True))
        self.window_overlap = dict(zip(self.fix_ends.tolist(), overlaps.tolist(), strict=True))
        if c.online.front_end == "pmf":
            self._terrain = online_fixes.window_terrain(survey, bathymetry, self.model)
            self._window_start = 0  # the first ping of the front end's next window
        # the point-mass windows and tracking tell the tide: the graph holds it (online_tide)
        calibration_std = graph_calibration_std(self.model)
        self.tide = c.online.learns_tide and calibration_std is not None and self.model.tide_variance > 0
        self._tide_mean, self._tide_joint = float(self.model.tide), np.zeros((6, 6))  # the latest key's
        self.tide_key, self.datum_key, self._tide_restart = TIDE, None, False  # (see online_tide)
        self._faults: list[tuple[int, float]] = []  # the depth faults since the last ordinary window
        self.tide_steps: list[int] = []  # the keys a new tide (or datum) was held from
        self._last_outcome: FixOutcome | None = None
        self.terrain = OnlineTerrain.of(self) if c.online.terrain == "soundings" else None
        self.acquisition = Acquisition.of(self) if c.online.acquire == "pmf" else None
        self.keys = key_indices(survey.time, self.fix_ends, c.key_interval)
        self._is_end = np.isin(np.arange(n), self.fix_ends)
        self._is_key = np.isin(np.arange(n), self.keys)
        # The previous key of every ping, and the DR increment (and covariance) from it.
        self._prev_key = self.keys[np.searchsorted(self.keys, np.arange(n), side="right") - 1]
        self._prev_key[self.keys[1:]] = self.keys[:-1]
        self._delta, self._delta_cov = increments(self.white, survey.time, survey.dr_pose,
                                                  self._prev_key, np.arange(n))
        m = self.model
        self.graph = PoseGraph(calibration_std, m.calibration_prior, self.origin, m.robust_kernel,
                               m.robust_parameter, m.odometry_min_std, m.odometry_min_heading_std)
        params = gtsam.ISAM2Params()
        threshold = gtsam.ISAM2ThresholdMap()  # per coordinate; the pose keys are plain integers
        threshold.insert(("\x00", np.array([c.online.relinearize_position, c.online.relinearize_position,
                                              c.online.relinearize_threshold])))
        threshold.insert(("c", np.array([1e-4, c.online.relinearize_threshold])))
        threshold.insert(("t", np.array([1e-3])))  # the tide (m), when held: a linear variable
        threshold.insert((online_tide.KEY_TIDE, np.array([1e-3])))  # a key pose's, when it drifts
        params.setRelinearizeThreshold(threshold)
        params.relinearizeSkip = c.online.relinearize_skip
        params.enablePartialRelinearizationCheck = True
        # iSAM2 inside GTSAM's fixed-lag smoother, which marginalises the key poses older than
        # its lag (their information stays as a linear factor on the newer ones) so that the work
        # per update stays bounded; the calibration's time stamp is renewed at every update.
        self.smoother = gtsam.IncrementalFixedLagSmoother(1e18, params)
        self.isam = self.smoother.getISAM2()
        self._new_factors = gtsam.NonlinearFactorGraph()
        self._new_values = gtsam.Values()
        self.index, self._extra_iterations = -1, 0  # the last ping processed; iSAM2 steps to add
        self._key_pose = np.zeros(3)  # DR frame
        self._key_joint = np.zeros((5, 5))  # (pose in DR-frame world coordinates, c)
        self._key_of = -1  # the key whose estimate _key_pose and _key_joint hold
        self.calibration = self.model.calibration_prior.copy()
        self.pose = np.full((n, 3), np.nan)
        self.covariance = np.full((n, 3, 3), np.nan)
        self.fixes: list[FixRecord] = []
        # what to do with each fix (use, hold, drop, lost, relocalise): decided by the policy
        self.policy = FixPolicy.from_config(c, float(min(bathymetry.cell_size)))
        self.state = PolicyState()
        # the start's position prior as in iSAM2 (widened when found wrong)
        self._start_factor: gtsam.NonlinearFactor | None = None
        self._remove: list[int] = []  # iSAM2 factor indices to remove at the next update
        self._residuals: dict[int, float] = {}  # the last windows' residual stds (_misfit_noise)
        self.step_times: list[float] = []
        self.update_times: list[float] = []
        self.tap_times: list[float] = []

    @property
    def lost(self) -> bool:
        """Whether the navigator is lost now (:mod:`tangraph.graph.policy`)."""
        return self.state.lost

    @property
    def episodes(self) -> tuple[LostEpisode, ...]:
        """The lost episodes so far."""
        return self.state.episodes

    # -- one step ------------------------------------------------------------------------------
    def predicted_frame(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """DR-frame pose of ping ``k`` and its joint covariance with the calibration ``(5, 5)``,
        from the latest key estimate and the DR increment."""
        return (compose(self._key_pose, self._delta[k]),
                propagate_joint(self._key_pose, self._key_joint, self._delta[k], self._delta_cov[k]))

    def predicted(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """World pose and covariance of ping ``k`` from the latest key estimate and the DR increment."""
        pose, joint = self.predicted_frame(k)
        return self._world(pose, joint)

    def _world(self, pose, joint) -> tuple[np.ndarray, np.ndarray]:
        return (to_world(pose, self.calibration, self.origin),
                world_covariance(pose, joint, self.calibration, self.origin))

    def step(self, fix: TerrainFix | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Process the next ping; returns its world pose ``(3,)`` and covariance ``(3, 3)``.

        Parameters
        ----------
        fix : TapFix or another TerrainFix, optional
            Use this fix of the ping (its ``index``) instead of making one; the ping becomes a key
            pose. It is judged like any other (quality flags, gate); a covariance that is not
            finite and positive definite raises a TangraphError naming the fix.
        """
        started = _time.perf_counter()
        k = self.index + 1
        if k >= self.survey.n_pings:
            raise TangraphError(f"the survey has {self.survey.n_pings} pings; all have been processed")
        if fix is not None and int(fix.index) != k:
            raise TangraphError(f"step of ping {k} was given a fix of ping {fix.index}")
        acquisition = self._acquiring()
        density = handover = None
        if acquisition is not None:  # the point-mass filter finds the vehicle (tangraph.graph.acquisition)
            density = acquisition.step(k)
            if density is not None and k > 0 and self._is_key[k]:
                handover = acquisition.ready(self, k)
        if k == 0:
            self._start(fix)
        elif self._is_key[k] or fix is not None:
            self._key_step(k, fix, handover)
        else:
            now = self.terrain.filtered(self, k) if self.terrain is not None else None
            self.pose[k], self.covariance[k] = self.predicted(k) if now is None else now
        if density is not None and self._acquiring() is not None:  # the filter's belief is the output
            self.pose[k, :2] = density[0]
            self.covariance[k, :2, :] = self.covariance[k, :, :2] = 0.0
            self.covariance[k, :2, :2] = density[1]
        self.index = k
        self.step_times.append(_time.perf_counter() - started)
        return self.pose[k].copy(), self.covariance[k].copy()

    def _start(self, fix: TerrainFix | None) -> None:
        dr = self.survey.dr_pose[0]
        m = self.model
        heading_std = max(m.heading_noise, m.odometry_min_heading_std)
        self.graph.add_pose(0, self.survey.time[0], dr)
        for factor in self.graph.add_start(0, dr, m.initial_position_std, heading_std):
            self._new_factors.add(factor)
        self._start_factor = self.graph._factors["start"][0]
        self._new_values.insert(0, gtsam.Pose2(*dr))
        if self.graph.calibrated:
            self._new_factors.add(self.graph._factors["prior"][0])
            self._new_values.insert(CALIBRATION, self.model.calibration_prior)
        if self.tide:  # in iSAM2 only: the batch smoother weighs the fixes' positions
            online_tide.start(self)
        joint = np.zeros((5, 5))
        joint[:2, :2] = np.eye(2) * m.initial_position_std**2
        joint[2, 2] = heading_std**2
        if self.graph.calibration_std is not None:
            joint[3:, 3:] = np.diag(self.graph.calibration_std**2)
        if self.acquisition is None or fix is not None:
            take_window(self, 0, dr, joint, fix)
        self._update(0)
        self._rebase(0)

    def _key_step(self, k: int, fix: TerrainFix | None, handover=None) -> None:
        """The key pose of ping ``k``: its odometry, the terrain factor or window ending there
        (``fix``: the one given to :meth:`step`), or the acquisition's ``handover`` (its factor's
        mean and covariance, :meth:`~tangraph.graph.acquisition.Acquisition.ready`), and the
        iSAM2 update."""
        prev = self.graph.keys[-1]
        if self.tide:
            online_tide.key_tide(self, prev, k)
        acquisition = self._acquiring()
        pose, joint = self.predicted_frame(k)
        self.graph.add_pose(k, self.survey.time[k], pose)
        start = pose.copy()
        if acquisition is not None:  # linearised at the filter's mean: the basin the exact posterior chose
            start[:2] = to_dr_frame(acquisition.mean, self.calibration, self.origin)
        self._new_values.insert(k, gtsam.Pose2(*start))
        grows = self.config.online.front_end == "pmf" and self._is_end[k] and fix is None
        if grows:
            self.window_first[k] = self._window_start
        if acquisition is not None:  # the graph tracks from the filter's belief only
            acquisition.before_key(self, prev)
        if self.terrain is not None:  # every sounding once the vehicle is found
            self.terrain.key_step(self, prev, k)
        # a start of tracking from the filter's belief is vetted by the filter after the update
        started = acquisition is not None and self.terrain is not None and self.terrain.tracking
        if acquisition is not None and handover is not None and not started:
            acquisition.hand_over(self, k, handover)
        if acquisition is not None:  # no window: the point-mass filter has the pings
            window = fix is not None
        else:
            window = self.terrain is None or fix is not None or self.terrain.window(self, k, pose, joint)
        extra = take_window(self, k, pose, joint, fix) if window else 0.0
        extra = extra if acquisition is None else acquisition.broken(extra)  # where it started afresh
        if grows:
            online_fixes.grow_window(self, k)
            if self.tide:
                online_fixes.tide_step(self, k)
        self._new_factors.add(self.graph.add_odometry(prev, k, self._delta[k], self._delta_cov[k],
                                                      break_std=extra))
        self._update(k, self._odometry_only(prev, extra, joint))
        if acquisition is not None and started:
            acquisition.vet(self, k, handover)
        self._rebase(k)

    def _acquiring(self) -> Acquisition | None:
        """The point-mass filter while it is finding the vehicle (None otherwise)."""
        return self.acquisition if self.acquisition is not None and self.acquisition.active else None

    def _odometry_only(self, prev: int, extra: float, predicted: np.ndarray) -> np.ndarray | None:
        """The new key's joint covariance with the calibration when the odometry from key ``prev``
        is all the update adds (no fix, break, removal or tide): the ``predicted`` joint (the
        latest key's carried by the increment) with the odometry factor's floors. If the update
        relinearises no other variable (:meth:`_update` checks) it is iSAM2's marginal (a linear
        chain grown by one between factor; marginalising old poses leaves it), for a fraction of
        a joint marginal's cost. None otherwise."""
        if extra > 0 or self._key_of != prev or self.tide or self._remove or self._new_factors.size() != 1:
            return None
        # between_noise's floors, isotropic in position: the same in the world as in the key's frame
        floor = [self.graph.min_std**2, self.graph.min_std**2, self.graph.min_heading_std**2, 0.0, 0.0]
        return predicted + np.diag(floor)

    def _rebase(self, k: int) -> None:
        """Make the pings up to the next planned key take their increments from key ``k`` (a
        fix given to :meth:`step` can add a key that was not planned)."""
        n = self.survey.n_pings
        if k + 1 >= n:
            return
        nxt = self.keys[np.searchsorted(self.keys, k, side="right")] if k < self.keys[-1] else n - 1
        idx = np.arange(k + 1, nxt + 1)
        idx = idx[self._prev_key[idx] != k]
        if idx.size:
            self._prev_key[idx] = k
            self._delta[idx], self._delta_cov[idx] = increments(
                self.white, self.survey.time, self.survey.dr_pose, np.full(idx.size, k), idx)

    # the window's fix: made, grown and judged in tangraph.graph.online_fixes
    def _judge(self, k: int, pose, joint, fix: TerrainFix | None, strict: bool = False) -> FixOutcome:
        self._last_outcome = online_fixes.judge(self, k, pose, joint, fix, strict)
        return self._last_outcome

    def _fix_factor(self, key: int, fix) -> gtsam.NonlinearFactor | None:
        return online_fixes.fix_factor(self, key, fix)

    def _grown(self, fix: TerrainFix, laid, joint) -> TerrainFix:
        return online_fixes.grown(self, fix, laid, joint)

    def _update(self, k: int, propagated: np.ndarray | None = None) -> None:
        """One iSAM2 update with the new factors; the estimate of key ``k`` and its joint
        covariance with the calibration (``propagated``: that joint carried from the latest
        key by :meth:`_odometry_only`, taken instead of the Bayes tree's joint marginal when the
        update marked no variable but the two the odometry joins)."""
        started = _time.perf_counter()
        stamps = gtsam.FixedLagSmootherKeyTimestampMap()
        for key in self._new_values.keys():
            stamps.insert((key, float(self.survey.time[k])))
        if self.graph.calibrated:  # the calibration is never old: it is never marginalised
            stamps.insert((CALIBRATION, float(self.survey.time[k])))
        for key in online_tide.held_keys(self):  # nor is the tide held (an earlier one after a step may go)
            stamps.insert((key, float(self.survey.time[k])))
        self.smoother.setSmootherLag(self._lag())
        try:
            self.smoother.update(self._new_factors, self._new_values, stamps, self._remove)
            for _ in range(self._extra_iterations):
                self.smoother.update(gtsam.NonlinearFactorGraph(), gtsam.Values(),
                                     gtsam.FixedLagSmootherKeyTimestampMap(), [])
        except RuntimeError as exc:
            raise translate_error(exc, self.graph) from None
        self._extra_iterations = 0
        self._new_factors = gtsam.NonlinearFactorGraph()
        self._new_values = gtsam.Values()
        self._remove = []
        self.isam = self.smoother.getISAM2()
        estimate = self.isam.calculateEstimatePose2(k)
        pose = np.array([estimate.x(), estimate.y(), estimate.theta()])
        pose[2] = wrap_near(pose[2], self.survey.dr_pose[k, 2])
        if self.graph.calibrated:
            self.calibration = np.asarray(self.isam.calculateEstimateVector(CALIBRATION), float)
        marked = self.smoother.getISAM2Result().getMarkedKeys()
        if propagated is not None and set(marked) <= {self._key_of, k}:
            self._key_joint = propagated  # the update marked only the two keys the odometry joins
        elif self.graph.calibrated:
            # the key pose with the calibration (and the tide when held), one joint marginal
            keys = (k, CALIBRATION, self.tide_key) if self.tide else (k, CALIBRATION)
            marginal = self.isam.jointMarginalCovariance(gtsam.KeyVector(list(keys)))
            full = np.block([[marginal.at(a, b) for b in keys] for a in keys])
            self._key_joint = joint_in_frame(pose[2], full[:5, :5])
            if self.tide:
                self._tide_mean = float(self.isam.calculateEstimateVector(self.tide_key)[0])
                self._tide_joint = joint_in_frame(pose[2], full)
        else:
            joint = np.zeros((5, 5))
            joint[:3, :3] = self.isam.marginalCovariance(k)
            self._key_joint = joint_in_frame(pose[2], joint)
        self._key_pose, self._key_of = pose, k
        self.update_times.append(_time.perf_counter() - started)
        self.pose[k], self.covariance[k] = self._world(self._key_pose, self._key_joint)

    def _lag(self) -> float:
        """Seconds of key poses kept: the newest ``isam_window`` key poses (all without a window)."""
        window = self.config.online.isam_window
        n = len(self.graph.keys)
        if window is None or n <= window:
            return 1e18
        times = self.graph.times
        return float(times[-1] - times[n - window]) + 1e-6

    @property
    def pending(self) -> tuple[int, int]:
        """Factors and values waiting for the next iSAM2 update (both 0 after every step)."""
        return int(self._new_factors.size()), int(self._new_values.size())

    # -- results -------------------------------------------------------------------------------
    def run(self, progress: bool = False) -> GraphNavigator:
        """Step through every remaining ping."""
        pings = range(self.index + 1, self.survey.n_pings)
        if progress:
            from tqdm import tqdm

            pings = tqdm(pings, desc="isam2", unit="ping")
        for _ in pings:
            self.step()
        return self

    def calibration_report(self, k: int | None = None) -> dict:
        """The calibration estimate after ping ``k`` (default the last one processed)."""
        k = self.index if k is None else k
        pose, joint = self.predicted_frame(k) if not self._is_key[k] else (self._key_pose, self._key_joint)
        return calibration_summary(self.calibration, joint, pose, self.survey.dr_pose[k, 2])

    def meta(self) -> dict:
        """The fix counts, the pings flagged lost (``n_lost``, ``lost_steps``: the fix policy's and
        the acquisition's), ``lost_episodes``, ``key_indices``, ``calibration``, the configuration
        and model, and the tide variable ``tide`` when held (its estimate and std, m)."""
        accepted = sum(f.accepted for f in self.fixes)
        lost = sorted({p for e in self.episodes for p in e.pings(self.index + 1)}
                      | set(self.acquisition.lost_steps() if self.acquisition is not None else ()))
        return {
            "n_fixes_accepted": int(accepted),
            "n_fixes_rejected": len(self.fixes) - int(accepted),
            "n_lost": len(lost),
            "lost_steps": lost,
            "lost_episodes": [e.as_dict() for e in self.episodes],
            "key_indices": [int(k) for k in self.graph.keys],
            "calibration": self.calibration_report(),
            **({"tide": online_tide.meta(self)} if self.tide else {}),
            **({"terrain": self.terrain.meta()} if self.terrain is not None else {}),
            **({"acquisition": self.acquisition.meta()} if self.acquisition is not None else {}),
            "config": self.config.as_dict(),
            "model": self.model.as_dict(),
        }

    def track(self) -> Track:
        """The online (causal) track of the pings processed so far (``method="isam2"``)."""
        done = self.index + 1
        if done < 1:
            raise TangraphError("no ping has been processed yet")
        steps = np.asarray(self.step_times)
        updates = np.asarray(self.update_times)
        timings = {
            "total": float(steps.sum()),
            "per_step": float(steps.mean()),
            "per_step_p99": float(np.percentile(steps, 99)),
            "update_mean": float(updates.mean()),
            "update_p99": float(np.percentile(updates, 99)),
            "tap_total": float(np.sum(self.tap_times)),
        }
        return Track(time=self.survey.time[:done], pose=self.pose[:done], covariance=self.covariance[:done],
                     method="isam2", timings=timings, meta=self.meta(), fixes=tuple(self.fixes))


def navigate_online(survey: Survey, bathymetry: BathymetryMap, config: GraphConfig | None = None, *,
                    model: NavigationModel | None = None, progress: bool = False) -> Track:
    """Online terrain-aided navigation of a survey on a pose graph solved by iSAM2.

    Parameters
    ----------
    survey : Survey
    bathymetry : BathymetryMap
    config : GraphConfig, optional
    model : NavigationModel, optional
        By default the one of a simulated survey (:meth:`NavigationModel.from_survey`; a
        TangraphError asks for one otherwise).
    progress : bool
        Show a progress bar.

    Returns
    -------
    Track
        ``method="isam2"``, one causal pose per ping with its covariance; ``timings`` has
        ``total``, ``per_step``, ``per_step_p99`` (whole steps, TAP included), ``update_mean``,
        ``update_p99`` (iSAM2 update and marginal of a key pose) and ``tap_total``; ``fixes``
        has one :class:`~tangraph.fix_records.FixRecord` per window (``index``, ``north``,
        ``east``, ``cov_nn``, ``cov_ne``, ``cov_ee`` (the covariance given to the graph: TAP's,
        counted once per ping where windows overlap, grown by what is uncertain of the
        calibrated patch), its :class:`~tangraph.fix_records.FixStatus` and ``detail``, ``nis`` and
        ``half_width``); ``meta`` has ``n_fixes_accepted``, ``n_fixes_rejected``, ``n_lost``,
        ``lost_steps`` and ``lost_episodes`` (:mod:`tangraph.graph.policy`), ``key_indices`` and
        ``calibration`` (:func:`calibration_summary` at the last ping).
    """
    return GraphNavigator(survey, bathymetry, config, model=model).run(progress).track()
