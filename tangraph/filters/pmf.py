"""The point-mass filter: the position density on a grid that moves with the estimate.

No particles: the density of the vehicle's position is held as its values on a regular
``n x n`` grid (Bergman's point-mass filter), every grid point weighed by the same terrain
likelihood as the particle filters (:mod:`tangraph.filters.likelihood`: the map's error, no map
is no evidence, MBARI's exponents, the tide marginalised exactly: each point carries its
Gaussian tide posterior, of the datum and its drift with a drifting tide, :mod:`tangraph.filters.tide`).
It is deterministic and keeps a multimodal density as it is.

**The DR's constant errors** ``(k, b)`` (speed scale, heading error) are held by default per
grid point: every point carries their Gaussian given that the vehicle is there (a
Rao-Blackwellised point-mass filter, :mod:`tangraph.filters.pmf_points`, where it is
described). With ``PMFConfig(calibration="bank")`` they are held by a bank instead: the
joint density of ``(position, k, b)`` is held at the nodes of a product Gauss-Hermite rule of a
Gaussian in the calibration (``calibration_points`` per principal axis), each node a member with
its own position grid and a mass. Between pings a member's grid moves by its own calibrated
increment ``R(-b) u / (1 + k)`` (the Lagrangian form: moving the points is exact); the white DR
noise accumulates and is convolved in (FFT, in the grid's coordinates) once its std reaches half
a grid spacing. A ping weighs every point of every member (but those of zero density: they stay
so whatever it says). The calibration's posterior is the Gaussian the nodes were placed with
times the evidence since (each member's mass over its mass at placement), fitted as a quadratic
at the nodes whose curvature is made a likelihood's (positive semi-definite): exact for a
Gaussian evidence however narrow against the nodes, never wider than the prior, its mean kept
among the nodes.

**Re-gridding**: when a member's density reaches its grid's edge, or the density has grown or
shrunk well away from its grid, every member is re-sampled (bilinear) onto a grid centred on its
own mean, aligned with the principal axes of the members' mean covariance, spanning
``grid_sigmas`` standard deviations and at least the points that hold all but ``1e-4`` of the
mass (so a second mode is not cut off). The calibration's nodes are re-placed then, and whenever
its posterior has moved from their placement: the Gauss-Hermite rule of the posterior (its
heading error grown by the heading walk since the last placement), each new node given the
position density of the nearest old member shifted by the regression of the members' mean
positions on the calibration (the posterior's position sensitivity to it, the walk since the
placement counted in the calibration's spread). The bank is for constant errors and a slow
walk: a heading error that may change by degrees at every turn (``heading_turn_std``) spreads
the nodes degrees apart after each turn, and their members' positions part by tens of metres
along the next line, between which the bank holds no point; where the terrain cannot choose
among them (a flat, poorly mapped shelf) it picks one with confidence. A particle filter
follows such a heading error (the caputh_replay study). When one
ping's evidence differs by more than ``_SHARP`` nats between the nodes and is Gaussian in the
calibration, the predicted state's nodes are first re-placed at the posterior it gives and the
ping weighed again (adaptive Gauss-Hermite quadrature). The tide posteriors of points mixed by
the convolution are moment-matched (the spread of the mixed means joins the variance);
re-sampling interpolates them.

**Resolution**: a grid point stands for its cell, so each sounding's variance is raised by the
variance of the map's depth across a cell, ``sum_i a_i^T G a_i / 12`` for the grid's steps
``a_i`` and the map's mean outer product of depth gradients ``G``: a coarse grid does not claim a
sharp likelihood it cannot resolve (negligible once the grid is finer than the likelihood).

The track is the density's mean and covariance (with the white noise not yet convolved in), the
heading the dead-reckoned one; ``meta["calibration"]`` is the mean and std of ``(k, b)`` (the
points' mixture, or the bank's).
A ping whose mean sounding's innovation is inconsistent with the density's predictive spread
(:class:`~tangraph.filters.steps.Innovation`'s ``nis``) for ``lost_pings`` pings in a row is
flagged lost with them (``meta["lost_steps"]``) and, with ``relocalise`` set, the filter starts
afresh from a uniform density on a global grid over the map's data (or ``relocalise_radius``
around its estimate; ``relocalise_points`` per axis), with one calibration node at the
calibration's prior, which the bank grows back from at its next re-grid, and the tide at its
prior (what a lost filter believes of them is suspect too). The density then holds every place
the soundings could have come from, and its covariance says so until the terrain has chosen
(``meta["relocalisation_steps"]``). With ``ping_gate`` an inconsistent ping does not weigh the
density, and ``gate_pings`` of them in a row start it afresh around its mean, wider, with the
tide and the calibration at their priors (:meth:`_Run.reopen`).

The filter and its run loop are here; the density on its grids (the state
:class:`~tangraph.filters.pmf_grid.PointMass`, the DR noise convolved in, re-gridding) is in
:mod:`tangraph.filters.pmf_grid`, the calibration bank (node placement, evidence fit) in
:mod:`tangraph.filters.pmf_bank`, its settings :class:`~tangraph.filters.config.PMFConfig` in
:mod:`tangraph.filters.config`.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import time as _time
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters import pmf_points
from tangraph.filters.belief import Belief
from tangraph.filters.config import PMFConfig
from tangraph.filters.likelihood import FilterDivergence, log_normalise
from tangraph.filters.model import FilterModel, Ping, survey_pings
from tangraph.filters.pmf_bank import _calibration_moved, _evidence_fit, _place_nodes
from tangraph.filters.pmf_grid import PointMass, _diffuse, _Grid, _regrid
from tangraph.filters.runner import check_run_inputs, step_timings
from tangraph.filters.steps import innovation
from tangraph.filters.tide import TideDrift, predict_tide, update_drift
from tangraph.geometry import rotate
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel, slope_moment, survey_navigation_model
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["PMFConfig", "point_mass_filter", "start_run"]

_log = logging.getLogger(__name__)
_VALUES_PER_POINT = 8  # the density, the tide's mean and the likelihood's temporaries per grid point


def _start(navigation: NavigationModel, centre: np.ndarray, grid: _Grid, config: PMFConfig,
           std: float | None = None) -> PointMass:
    """The start's density: a Gaussian of ``std`` (m; None: the model's initial position std)
    around ``centre``, the calibration and the tide at their priors."""
    cal_mean = np.asarray(navigation.calibration_prior, dtype=np.float64)
    cal_std = np.asarray(navigation.calibration_std, dtype=np.float64)
    per_point = config.calibration == "points"
    nodes, log_weight = _place_nodes(cal_mean, np.diag(cal_std**2),
                                     (1, 1) if per_point else config.calibration_points)
    s = navigation.initial_position_std if std is None else std
    axes = grid.axes(np.eye(2) * s**2)
    h = (grid.n - 1) / 2.0
    i, j = np.meshgrid(np.arange(grid.n) - h, np.arange(grid.n) - h, indexing="ij")
    offsets = np.column_stack([i.ravel(), j.ravel()]) @ axes.T
    log_p = -0.5 * np.sum(offsets**2, axis=1) / max(s, 1e-9) ** 2
    density = (log_weight[:, None] + log_p[None]).reshape(len(nodes), grid.n, grid.n)
    _, log_total = log_normalise(density.ravel(), where="pmf")
    area = float(abs(np.linalg.det(axes)))
    state = PointMass(nodes, log_weight, np.tile(centre, (len(nodes), 1)), axes,
                      density - log_total - np.log(area), np.full(density.shape, navigation.tide),
                      navigation.tide_variance, np.zeros((2, 2)), 0.0, (cal_mean, np.diag(cal_std**2)),
                      (cal_mean, cal_std), tide_drift=TideDrift.start(navigation, density.shape))
    return _per_point(state, cal_mean, np.diag(cal_std**2)) if per_point else state


def _per_point(state: PointMass, cal_mean: np.ndarray, cal_cov: np.ndarray) -> PointMass:
    """``state`` (one member) with every point's calibration at ``(cal_mean, cal_cov)``."""
    size = state.log_density.size
    state.point_cal = np.tile(cal_mean, (size, 1))
    state.shift = np.zeros((size, 2))
    state.joint = pmf_points.start_joint(cal_cov)
    return state


def _predict(state: PointMass, ping: Ping, model: FilterModel) -> None:
    if ping.first:
        return
    if state.point_cal is not None:
        pmf_points.predict(state, ping, model.motion)
        state.tide, state.tide_var, state.tide_drift = predict_tide(
            state.tide, state.tide_var, state.tide_drift, model.navigation, ping)
        return
    step = rotate(-state.nodes[:, 1], np.broadcast_to(ping.increment, state.centres.shape))
    state.centres = state.centres + step / (1.0 + state.nodes[:, 0])[:, None]
    state.pending = state.pending + model.motion.noise_covariance(ping)
    state.walk += model.motion.walk_variance(ping)
    state.tide, state.tide_var, state.tide_drift = predict_tide(state.tide, state.tide_var, state.tide_drift,
                                                                model.navigation, ping)
    inv = np.linalg.inv(state.axes)
    if np.max(np.linalg.eigvalsh(inv @ state.pending @ inv.T)) >= 0.25:
        _diffuse(state)


def _update(state: PointMass, ping: Ping, model: FilterModel, slope: np.ndarray):
    """Weigh the state's points by the ping; returns the ping's innovation check and the terrain
    update (of the points weighed), or ``(None, None)``. Points of zero density (``-inf``: they
    stay so whatever the ping says) are not weighed: the other points' likelihoods are the same
    as if they were (a point of zero weight counts for nothing in the sub-cloud means and
    exponents), their tide means are kept."""
    if ping.n_soundings == 0:
        return None, None
    log_mass = (state.log_density - np.max(state.log_density)).ravel()
    live = np.flatnonzero(log_mass > -np.inf)
    log_mass = log_mass[live]
    weights = np.exp(log_mass)
    points = np.take(state.points(), live, axis=0)
    tide = state.tide.ravel()[live]
    turn = state.heading_errors()[live]
    resolution = float(np.trace(state.axes.T @ slope @ state.axes)) / 12.0
    update = model.terrain.evaluate(
        points, tide, state.tide_var, ping, turn, weights=weights, scale=state.misfit,
        extra_variance=resolution,
    )  # fmt: skip
    if np.all(np.isneginf(update.log_likelihood)):
        return None, None  # no point has the map under any sounding: no information
    view = Belief(points, log_mass - np.log(weights.sum()), tide, state.tide_var,
                  np.empty((points.shape[0], 0)), np.empty(0))
    check = innovation(view, update, ping, model)
    log_likelihood = update.log_likelihood
    if state.point_cal is not None:  # the swath's evidence on each point's heading error
        log_likelihood = pmf_points.swath_heading(
            state, live, log_mass, log_likelihood, lambda sub, turn, move: model.terrain.evaluate(
                points[sub] + move, tide[sub], state.tide_var, ping, turn, weights=weights[sub],
                earlier=update, scale=state.misfit, extra_variance=resolution).log_likelihood,
            ping.offsets)
    flat = state.log_density.ravel()
    posterior = np.full(flat.shape, -np.inf)
    posterior[live] = flat[live] + log_likelihood
    _, log_total = log_normalise(posterior, where=f"pmf ping {ping.index}")
    state.log_density = (posterior - log_total - np.log(state.cell_area)).reshape(state.log_density.shape)
    flat_tide = state.tide.ravel().copy()
    flat_tide[live] = update.tide
    new_tide = flat_tide.reshape(state.tide.shape)
    state.tide_drift = update_drift(state.tide_drift, state.tide, state.tide_var, new_tide, update.tide_var)
    state.tide, state.tide_var = new_tide, update.tide_var
    if update.scale is not None:  # (without a misfit scale there is nothing to update)
        state.misfit = update.scale_after(np.exp(posterior[live] - np.max(posterior)))
    return check, update


# A ping whose evidence differs by more than this (nats) between calibration nodes tells the
# calibration more sharply than the nodes can hold: they are re-placed at its posterior first.
_SHARP = 8.0
_MAX_REFINE = 2


def _measure(state: PointMass, ping: Ping, model: FilterModel, slope: np.ndarray, grid: _Grid,
             config: PMFConfig, estimate: bool):
    """The ping's update (:func:`_update`) as a new state. With the calibration estimated, when
    the ping's evidence is too sharp across the nodes, the predicted state's nodes are re-placed
    at the posterior the ping gives (adaptive Gauss-Hermite quadrature) and the ping weighed
    again, at most ``_MAX_REFINE`` times."""
    for attempt in range(_MAX_REFINE + 1):
        trial = state.copy()  # fields are replaced, never changed in place
        check, update = _update(trial, ping, model, slope)
        if update is None or attempt == _MAX_REFINE:
            return trial, check, update
        if not estimate:
            return trial, check, update
        prior = state.member_log_mass()
        evidence = trial.member_log_mass() - prior
        live = np.isfinite(evidence) & (prior > np.max(prior) - 20.0)
        if not live.any() or np.ptp(evidence[live]) <= _SHARP:
            return trial, check, update
        mean, cov, concave = _evidence_fit(trial.nodes, trial.member_log_mass() - trial.node_base,
                                           *trial.prior)
        if not concave:  # not a Gaussian in the calibration: the nodes cannot be aimed by it
            return trial, check, update
        cov[1, 1] += state.walk
        state = _regrid(state, grid, config, True, target=(mean, cov))
    return trial, check, update  # not reached


def _inconsistent(check, alpha: float) -> bool:
    """The lost test of one ping: its mean sounding's innovation against the density's own
    predictive spread (:meth:`~tangraph.filters.steps.Innovation.nis_beyond`: chi-square(1), or
    the Student-t tail of the map's local misfit scale). The best point's chi-square is not
    used: the calibration's few nodes need not hold a point that fits every sounding of a wide
    swath while the heading error is still uncertain."""
    return check.nis_beyond(alpha)


def _relocalised(state: PointMass, bathymetry: BathymetryMap, navigation: NavigationModel,
                  config: PMFConfig, centre: np.ndarray) -> PointMass:
    """A uniform density on the global grid (see the module docstring)."""
    rows, cols = np.nonzero(np.isfinite(bathymetry.depth))
    low = np.array([bathymetry.north[rows.min()], bathymetry.east[cols.min()]])
    high = np.array([bathymetry.north[rows.max()], bathymetry.east[cols.max()]])
    if config.relocalise_radius is not None:
        low = np.maximum(low, centre - config.relocalise_radius)
        high = np.minimum(high, centre + config.relocalise_radius)
        if np.any(high <= low):  # the estimate is far off the map's data: around it then
            low, high = centre - config.relocalise_radius, centre + config.relocalise_radius
    n = config.relocalise_points
    axes = np.diag(np.maximum((high - low) / (n - 1), config.min_spacing))
    cal_mean = np.asarray(navigation.calibration_prior, dtype=np.float64)  # a lost filter's: suspect
    cal_cov = np.diag(np.asarray(navigation.calibration_std, dtype=np.float64) ** 2)
    area = float(abs(np.linalg.det(axes))) * n * n
    out = PointMass(cal_mean[None, :], np.zeros(1), (0.5 * (low + high))[None, :], axes,
                    np.full((1, n, n), -np.log(area)), np.full((1, n, n), navigation.tide),
                    navigation.tide_variance, np.zeros((2, 2)), 0.0, (cal_mean, cal_cov),
                    (cal_mean, np.sqrt(np.maximum(np.diag(cal_cov), 0.0))), state.misfit,
                    TideDrift.start(navigation, (1, n, n)))
    return _per_point(out, cal_mean, cal_cov) if config.calibration == "points" else out


@dataclasses.dataclass(eq=False)
class _Run:
    """A run of the point-mass filter: what every ping uses and what the run records (the
    diverged, off-map, lost and relocalisation pings, the lost streak, the re-grids)."""

    bathymetry: BathymetryMap
    navigation: NavigationModel
    model: FilterModel
    config: PMFConfig
    grid: _Grid
    slope: np.ndarray
    estimate: bool  # whether the calibration is estimated (a bank of more than one node)
    lost_steps: list[int] = dataclasses.field(default_factory=list)
    gated_steps: list[int] = dataclasses.field(default_factory=list)
    reopened: list[tuple[int, float]] = dataclasses.field(default_factory=list)  # (ping, widening std)
    off_map_steps: list[int] = dataclasses.field(default_factory=list)
    divergence_steps: list[int] = dataclasses.field(default_factory=list)
    relocalisation_steps: list[int] = dataclasses.field(default_factory=list)
    streak: int = 0
    n_regrids: int = 0

    def step(self, state: PointMass, ping: Ping) -> PointMass:
        """The state after ``ping``: predicted, weighed, tested for lost, re-gridded if due."""
        _predict(state, ping, self.model)
        if state.point_cal is not None:  # the spread in before the ping weighs it (as the bank's noise)
            state = self.regrid_points(state)
        if self.config.ping_gate and self.streak == self.config.gate_pings - 1:
            state = self.reopen(state, ping)
        predicted = state
        try:
            state, check, update = _measure(state, ping, self.model, self.slope, self.grid, self.config,
                                            self.estimate)
        except FilterDivergence:  # no point of positive density explains the ping: keep the prior
            self.divergence_steps.append(ping.index)
            check, update = None, False
        if (self.config.ping_gate and check is not None and _inconsistent(check, self.config.lost_alpha)
                and self.streak < self.config.gate_pings - 1):  # (a streak this long: the density is wrong)
            state = predicted
            self.gated_steps.append(ping.index)
        if update is None and ping.n_soundings:
            self.off_map_steps.append(ping.index)
        if check is not None or update is False:
            state = self.lost_test(state, ping, check, update)
        if state.point_cal is not None:
            return self.regrid_points(state)
        if self.grid.needs_regrid(state, state.within()) or (self.estimate and _calibration_moved(state)):
            state = _regrid(state, self.grid, self.config, self.estimate)
            self.n_regrids += 1
        return state

    def regrid_points(self, state: PointMass) -> PointMass:
        """With the calibration per point: a new grid when the density with the points' shared
        spread needs one, else the same grid once the spread reaches half a step
        (:func:`~tangraph.filters.pmf_points.regrid`)."""
        spread = state.joint[:2, :2] if state.joint is not None else np.zeros((2, 2))
        if self.grid.needs_regrid(state, state.within() + spread):
            self.n_regrids += 1
            return pmf_points.regrid(state, self.grid)
        inv = np.linalg.inv(state.axes)
        if np.max(np.linalg.eigvalsh(inv @ spread @ inv.T)) >= pmf_points.SPREAD:
            return pmf_points.regrid(state, self.grid, keep=True)
        return state

    def reopen(self, state: PointMass, ping: Ping) -> PointMass:
        """The gate's way out (``PMFConfig.gate_pings``): the density is wrong, not the pings. It
        starts afresh around its mean, wider by the PF's re-initialisation spread (``3 max(s,
        1)``, ``s`` the model's start std), with the tide and the calibration at their priors (a
        start on bad depths, a step of the water level, a block of bad pings followed, a start
        farther off than stated all leave a density no later ping agrees with). The spread does
        not grow at further way-outs, as the PF's redraw: on the demo's surveys with a start
        200 m off, doubling it took three runs in twelve to a wrong place kilometres off. The
        local misfit scale goes back to its prior too (it had been learnt from a wrong density;
        it used to be dropped, leaving the stated errors trusted from there on)."""
        mean, cov = state.moments()
        spread = 3.0 * max(self.navigation.initial_position_std, 1.0)
        std = float(np.hypot(np.sqrt(np.max(np.linalg.eigvalsh(cov))), spread))
        _log.info("pmf: %d pings in a row it cannot explain at ping %d: afresh around its mean, %.0f m wide",
                  self.streak, ping.index, std)
        self.reopened.append((ping.index, std))
        state = _start(self.navigation, mean, self.grid, self.config, std=std)
        state.misfit = self.model.misfit_prior()
        return state

    def lost_test(self, state: PointMass, ping: Ping, check, update) -> PointMass:
        """The lost streak after ``ping`` (its innovation ``check``; ``update`` False: it
        diverged); with ``relocalise``, a lost filter starts afresh on the global grid."""
        config = self.config
        self.streak = self.streak + 1 if update is False or _inconsistent(check, config.lost_alpha) else 0
        if self.streak == config.lost_pings:  # the streak's pings all said so
            self.lost_steps.extend(range(ping.index - self.streak + 1, ping.index))
        if self.streak >= config.lost_pings:
            self.lost_steps.append(ping.index)
            if config.relocalise and state.n <= self.grid.n:  # not while searching the global grid
                _log.warning("pmf: lost at ping %d; relocalising on the global grid", ping.index)
                state = _relocalised(state, self.bathymetry, self.navigation, config, state.moments()[0])
                self.relocalisation_steps.append(ping.index)
                self.streak = 0
        return state

    def meta(self, state: PointMass, n_pings: int) -> dict[str, Any]:
        """The track's ``meta`` (see :func:`point_mass_filter`)."""
        cal_mean, cal_cov = state.calibration()
        cal_std = np.sqrt(np.maximum(np.diag(cal_cov), 0.0))
        return {
            "calibration": {
                "speed_scale": float(cal_mean[0]),
                "speed_scale_std": float(cal_std[0]),
                "heading_error": float(cal_mean[1]),
                "heading_error_std": float(np.sqrt(cal_std[1] ** 2 + state.walk)),
            },
            "ess": [float("nan")] * n_pings,
            "n_resampled": 0,
            "n_divergences": len(self.divergence_steps),
            "divergence_steps": self.divergence_steps,
            "n_lost": len(self.lost_steps),
            "lost_steps": self.lost_steps,
            "gated_steps": self.gated_steps,
            "reopened_steps": [p for p, _ in self.reopened],
            "n_off_map": len(self.off_map_steps),
            "off_map_steps": self.off_map_steps,
            "relocalisation_steps": self.relocalisation_steps,
            "n_regrids": self.n_regrids,
            "n_points": int(len(state.nodes) * self.grid.n**2),
            "sounding_std": self.model.terrain.sounding_std,
            "navigation_model": self.navigation.as_dict(),
            "config": self.config.as_dict(),
            "seed": None,
        }


def _check_memory(config: PMFConfig, n_beams: int) -> None:
    """Refuse, naming the setting, a grid whose weighing would need more than half of this
    machine's memory (every point of every calibration node holds a few values and, while a ping
    is weighed, one residual per sounding)."""
    total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    nodes = 1 if config.calibration == "points" else math.prod(config.calibration_points)
    grids = [("grid_points", config.grid_points, nodes)]
    if config.relocalise:
        grids.append(("relocalise_points", config.relocalise_points, 1))
    for name, points, nodes in grids:
        need = nodes * points**2 * 8 * (_VALUES_PER_POINT + n_beams)
        if need > total / 2:
            at = f" at {nodes} calibration nodes" if nodes > 1 else ""
            raise TangraphError(
                f"PMFConfig.{name} = {points}: weighing a grid of {points} x {points} points{at} needs "
                f"about {need / 2**30:.1f} GiB, more than half of this machine's {total / 2**30:.0f} GiB"
            )


def start_run(survey: Survey, bathymetry: BathymetryMap, navigation: NavigationModel,
              config: PMFConfig) -> tuple[_Run, PointMass, list[Ping]]:
    """A run of the filter over ``survey`` under ``navigation`` (a checked model): the run, its
    state before the first ping (the start's prior) and every ping. ``state = run.step(state,
    pings[k])`` for ``k = 0, 1, ...`` is the filter; the online graph's acquisition
    (:mod:`tangraph.graph.acquisition`) steps it so."""
    _check_memory(config, survey.beam_depth.shape[1])
    filter_model = FilterModel.from_model(navigation, bathymetry)
    grid = _Grid(config, config.min_spacing)
    estimate = config.calibration == "bank" and any(
        c > 1 and s > 0 for c, s in zip(config.calibration_points, navigation.calibration_std, strict=True))
    state = _start(navigation, survey.dr_pose[0, :2].astype(np.float64), grid, config)
    state.misfit = filter_model.misfit_prior()
    run = _Run(bathymetry, navigation, filter_model, config, grid, slope_moment(bathymetry), estimate)
    return run, state, survey_pings(survey, bathymetry, navigation)


def point_mass_filter(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: PMFConfig | None = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator | None = None,
    progress: bool = False,
) -> Track:
    """Run the point-mass filter over a survey (deterministic: ``rng`` is not used); ``model``
    is the navigation model (None: ``NavigationModel.from_survey(survey)``). See the module
    docstring.

    Returns
    -------
    Track
        The density's mean track and covariance (heading: dead reckoning, its variance NaN);
        ``meta``: ``calibration`` (its mean and std), ``n_lost``, ``lost_steps``,
        ``n_off_map``, ``off_map_steps`` (pings no point had the map under),
        ``relocalisation_steps`` (pings after which it started afresh on the global grid),
        ``n_regrids``,
        ``n_points`` (grid points per ping: members times ``grid_points^2``),
        ``navigation_model``, ``config``; ``timings``.
    """
    from tqdm.auto import tqdm

    check_run_inputs(survey, bathymetry, rng, where="pmf", rng_optional=True)
    config = config or PMFConfig()
    navigation = survey_navigation_model(survey, model, where="pmf", bathymetry=bathymetry)
    run, state, pings = start_run(survey, bathymetry, navigation, config)
    k_total = survey.n_pings
    mean = np.empty((k_total, 2))
    cov = np.full((k_total, 3, 3), np.nan)
    seconds = np.empty(k_total)
    started = _time.perf_counter()
    for ping in tqdm(pings, disable=not progress, desc="pmf", unit="ping", leave=False):
        t0 = _time.perf_counter()
        state = run.step(state, ping)
        m, c = state.moments()
        mean[ping.index], cov[ping.index, :2, :2] = m, c
        seconds[ping.index] = _time.perf_counter() - t0
    elapsed = _time.perf_counter() - started
    return Track(
        time=survey.time,
        pose=np.column_stack([mean, survey.dr_pose[:, 2]]),
        covariance=cov,
        method="pmf",
        timings=step_timings(elapsed, seconds),
        meta=run.meta(state, k_total),
    )
