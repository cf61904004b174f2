"""The online graph's acquisition by a point-mass filter: the exact Bayesian filter finds the
vehicle, the graph tracks it.

With ``GraphConfig.online.acquire = "pmf"`` (and ``terrain = "soundings"``) the online navigator
does not search TAP windows to find the vehicle. A point-mass filter of the navigator's own
navigation model (:mod:`tangraph.filters.pmf`: the same start prior, DR model, calibration bank
and terrain likelihood) is stepped over the pings from the first, and its density's mean and
covariance are the navigator's output until the graph tracks. The filter keeps every place the
soundings allow, multimodal or not, as FFI's HUGIN and MBARI's TRN do before they trust a
Gaussian.

**What the graph receives.** At each key pose while the filter runs, when its density is *one
part* (on a grid laid on its moments, ``posterior_fix.GRID_POINTS`` per axis over
``posterior_fix.GRID_SIGMAS`` stds, every calibration member's density summed: no second
connected region above ``exp(-MODE_LEVEL)`` of the peak holds ``MODE_MASS`` of the mass, and the
grid's outer ring holds at most ``EDGE_MASS``: :mod:`tangraph.graph.posterior_fix`'s tests) and
its information exceeds the graph's prediction's (``posterior_fix``'s ``MIN_GAIN`` and
``MAX_LOSS``), the graph receives the filter's terrain information on the key's world position,
and on the tide when the graph holds it (the density's moments over both, every point's tide
posterior pooled): the posterior's information less the prediction's, ``N(L^-1 (S^-1 mu - P^-1
m), L^-1)`` with ``L = S^-1 - P^-1`` (``posterior_fix._remove_prior``). The prediction holds what
earlier keys received, so each factor carries what the filter learnt since, nothing is counted
twice, and the graph's belief at the key is the filter's. No window is made meanwhile, and
every key pose is linearised at the filter's mean: the basin the exact posterior chose, not the
one nearest the DR's prediction. The filter runs with its ping gate (``PMFConfig.ping_gate``: a
ping its density cannot explain, as in a block of bad depths, does not weigh it), and a factor
whose information lies beyond the graph's prediction (its NIS against the prediction beyond the
``chi2`` quantile ``GraphConfig.fixes.gate_probability``) is not given: a filter dragged off
would otherwise throw the graph's calibration out. Nor is a factor given while the filter is
lost (its lost test's streak), and the pings it flags lost are flagged lost in the track. When
the gate's way out starts the filter afresh, wider and with the tide at its prior, the graph
follows: a break of the same width on the odometry into its next key pose, and a new tide
variable (:func:`~tangraph.graph.online_tide.new_tide`).

**The hand-over.** A key step after a key that received the filter's factor (so that the
graph's belief is the filter's), once the density has converged there (at most half the start
prior's variance along every axis: the terrain has told the position at least as much as the
prior did; on smooth terrain a belief as wide as the prior passes the tangent-plane test, and
linearised soundings then settle in whichever basin lies under it), asks whether the graph can
track
(:meth:`~tangraph.graph.online_terrain.OnlineTerrain.key_step`: the map near its tangent plane
over the belief, under the footprints of the pings since that key). When it does, those pings
enter the graph as its first terrain factor, linearised there, and the update is checked
against the filter, which weighed the same pings exactly: when the graph's position at the new
key lies beyond the ``chi2(2)`` quantile ``VET_PROBABILITY`` of the filter's density, or its
variance along some axis is below ``VET_NARROWER`` of the filter's (the linearised soundings
claim more than the exact filter found in them: on the drifting-tide demo survey a start
passed the tangent-plane test with the filter's density 5 m wide along one axis and left the
graph 2 m wide there, 8 m off), the start is undone (its factor taken out, the filter's factor
given instead) and the filter goes on.
Otherwise the filter stops (its information since the last factor is dropped with it, so
nothing is counted twice), the fix policy starts, and when tracking ends later the TAP windows
and the fix policy take over as without acquisition.
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time
from typing import TYPE_CHECKING

import numpy as np
from scipy import stats

from tangraph.errors import TangraphError
from tangraph.filters import pmf
from tangraph.filters.config import PMFConfig
from tangraph.filters.likelihood import FilterDivergence
from tangraph.filters.pmf_grid import _sample
from tangraph.fix_records import FixRecord, FixStatus
from tangraph.geometry import gate_threshold, mahalanobis2
from tangraph.graph import posterior_fix as pf
from tangraph.graph.calibration import position_tide_factor
from tangraph.graph.online_fixes import position_tide_prior
from tangraph.graph.online_terrain import START_ITERATIONS
from tangraph.graph.online_tide import new_tide, of_key

if TYPE_CHECKING:
    from tangraph.filters.model import Ping
    from tangraph.filters.pmf_grid import PointMass
    from tangraph.graph.online import GraphNavigator
    from tangraph.graph.online_terrain import OnlineTerrain

__all__ = ["HANDOVER_DETAIL", "VET_NARROWER", "VET_PROBABILITY", "Acquisition"]

HANDOVER_DETAIL = "point-mass acquisition: its posterior less the prediction"
#: A start of tracking whose position is beyond this chi2(2) quantile of the filter's density is undone
VET_PROBABILITY = 0.999
_VET_NIS = float(stats.chi2.ppf(VET_PROBABILITY, 2))
#: ... or whose position's variance is below this share of the filter's along an axis: the
#: linearised soundings claim more than the exact filter found in the same pings
VET_NARROWER = 0.5

log = logging.getLogger("tangraph.graph.online")


@dataclasses.dataclass(eq=False)
class Acquisition:
    """The point-mass filter of one online run until the graph tracks (``handover``: that key,
    None before), with its state and pings, the keys it gave the graph a factor at, the
    tracking starts it undid, the density's position ``mean`` and ``cov`` after the latest ping
    and the seconds it took."""

    run: pmf._Run
    state: PointMass
    pings: list[Ping]
    handover: int | None = None
    factors: list[int] = dataclasses.field(default_factory=list)
    undone: list[int] = dataclasses.field(default_factory=list)
    mean: np.ndarray = dataclasses.field(default_factory=lambda: np.full(2, np.nan))
    cov: np.ndarray = dataclasses.field(default_factory=lambda: np.full((2, 2), np.nan))
    seconds: float = 0.0
    last_reason: str = ""
    converged: bool = False  # the density at the latest factor had converged (before_key)
    diverged: int | None = None  # the ping at which the filter diverged
    reopened_seen: int = -1  # the latest ping the filter started afresh at, as the graph knows (ready)
    break_std: float = 0.0  # the break (m) the next key's odometry takes for it (online._key_step)

    @classmethod
    def of(cls, nav: GraphNavigator) -> Acquisition:
        settings = PMFConfig(ping_gate=True)
        run, state, pings = pmf.start_run(nav.survey, nav.bathymetry, nav.model, settings)
        return cls(run, state, pings)

    @property
    def active(self) -> bool:
        return self.handover is None and self.diverged is None

    def step(self, k: int) -> tuple[np.ndarray, np.ndarray] | None:
        """The filter after ping ``k``: its position mean ``(2,)`` and covariance ``(2, 2)``; None
        when it has diverged (no point of its density left: the windows and the fix policy
        then find the vehicle, as without acquisition, and ``diverged`` is that ping)."""
        started = _time.perf_counter()
        try:
            self.state = self.run.step(self.state, self.pings[k])
        except FilterDivergence as exc:
            log.warning("graph: the point-mass acquisition diverged at ping %d (%s): windows now", k, exc)
            self.diverged = k
            return None
        self.mean, self.cov = self.state.moments()
        self.seconds += _time.perf_counter() - started
        return self.mean, self.cov

    def ready(self, nav: GraphNavigator, k: int):
        """The graph's factor at key ``k`` when the filter's density after ping ``k`` is one part
        and tells more than the graph's prediction: ``(mean, covariance)`` over the world position,
        and the tide when the graph holds it; None otherwise (``last_reason`` says why)."""
        mean, cov = self.mean, self.cov  # after ping k (step)
        reopened = [(p, std) for p, std in self.run.reopened if p > self.reopened_seen]
        if reopened:  # the filter started afresh: so does the graph's belief, which holds what it gave
            self.reopened_seen = reopened[-1][0]
            self.break_std = float(np.hypot.reduce([std for _, std in reopened]))
            if nav.tide:
                new_tide(nav, k, nav.model.tide)
            self.last_reason = "the filter started afresh since the last key: a break into this key"
            log.info("graph: a break of %.0f m into key %d and a new tide: the point-mass filter "
                     "started afresh", self.break_std, k)
            return None
        if self.run.streak >= self.run.config.lost_pings:
            self.last_reason = f"lost: {self.run.streak} pings in a row it cannot explain"
            return None
        if not np.all(np.isfinite(cov)) or np.linalg.eigvalsh(cov).min() <= 0:
            self.last_reason = "degenerate density"
            return None
        reason = _shape(self.state, mean, cov)
        if reason:
            self.last_reason = reason
            return None
        world, world_cov = nav.predicted(k)
        prior_mean, prior_cov = position_tide_prior(nav, k, world, world_cov)
        mean3, cov3 = _with_tide(self.state, mean, cov)
        n = 3 if nav.tide else 2
        reasons: list[str] = []
        factor = pf._remove_prior(mean3[:n], cov3[:n, :n], prior_mean[:n], prior_cov[:n, :n], reasons)
        self.last_reason = "; ".join(reasons)
        if factor is not None:  # what the filter learnt must be something the prediction allows
            nis = float(mahalanobis2(factor[0] - prior_mean[:n], factor[1] + prior_cov[:n, :n]))
            if nis > gate_threshold(nav.config.fixes.gate_probability or VET_PROBABILITY, n):
                self.last_reason = f"its information is beyond the graph's prediction (NIS {nis:.0f})"
                return None
        return factor

    def hand_over(self, nav: GraphNavigator, k: int, factor) -> None:
        """Put the filter's ``factor`` (:meth:`ready`) on key pose ``k`` (added to the navigator's
        new factors, no robust kernel: it is a posterior, not a candidate; the update that adds it
        is iterated, ``START_ITERATIONS``, as the belief it gives may lie metres from where the
        graph linearised); the pings up to ``k`` are the filter's."""
        mean, cov = factor
        position, covariance = mean[:2], cov[:2, :2]
        joint = position_tide_factor(k, mean, cov, nav.origin, "none", tide_key=of_key(nav, k)) \
            if mean.size == 3 else None
        made = nav.graph.fix_factor(k, position, covariance, kernel="none") if joint is None else joint
        nav._new_factors.add(nav.graph.add_position_fix(k, position, covariance, made))
        nav.fixes.append(FixRecord.of(k, _Fix(position, covariance), FixStatus.ACCEPTED, float("nan"),
                                      float("nan"), HANDOVER_DETAIL))
        _tracker(nav).handed_over(k)
        nav._extra_iterations = START_ITERATIONS
        self.factors.append(k)
        # converged: the terrain has told the position at least as much as the start's prior did
        start = nav.model.initial_position_std**2
        self.converged = bool(np.linalg.eigvalsh(self.cov).max() <= 0.5 * start)

    def broken(self, extra: float) -> float:
        """The break (std, m) on the odometry into this key: ``extra`` and the filter's widening
        since the last key (:meth:`ready`), taken once."""
        extra, self.break_std = float(np.hypot(extra, self.break_std)), 0.0
        return extra

    def before_key(self, nav: GraphNavigator, prev: int) -> None:
        """Before the key step after key ``prev``: the graph may start tracking only from a
        belief that is the filter's and has converged, so only when ``prev`` received the
        filter's factor with its density at most half the start's prior variance along every
        axis."""
        if self.factors[-1:] != [prev] or not self.converged:
            _tracker(nav).found = False

    def vet(self, nav: GraphNavigator, k: int, factor) -> None:
        """The graph has started tracking at key ``k`` and been updated: keep it (the filter is
        done) when its position there agrees with the filter's density (NIS within the
        ``chi2(2)`` quantile ``VET_PROBABILITY``, and its variance along every axis at least
        ``VET_NARROWER`` of the filter's); else undo the start (its terrain factor taken
        out of iSAM2, tracking stopped) and put the filter's ``factor`` (:meth:`ready`, made on
        the prediction before the start; None: none) on key ``k`` instead, the filter going on."""
        world, world_cov = nav._world(nav._key_pose, nav._key_joint)
        nis = float(mahalanobis2(world[:2] - self.mean, self.cov + world_cov[:2, :2]))
        # the graph's variance along each axis against the filter's (the generalised eigenvalues)
        narrow = float(np.linalg.eigvals(np.linalg.solve(self.cov, world_cov[:2, :2])).real.min())
        if nis <= _VET_NIS and narrow >= VET_NARROWER:
            self.handover = k
            return
        log.info("graph: tracking from key %d undone: %.1f m from the point-mass filter's mean (NIS %.1f), "
                 "%.2f of its variance", k, float(np.hypot(*(world[:2] - self.mean))), nis, narrow)
        _tracker(nav).undo_start(nav)
        self.undone.append(k)
        if factor is not None:
            self.hand_over(nav, k, factor)
        nav._update(k)

    def lost_steps(self) -> list[int]:
        """The pings the filter flagged lost (its lost test) while it was the navigator's output."""
        end = self.handover if self.handover is not None else self.diverged
        return [int(p) for p in self.run.lost_steps if end is None or p < end]

    def meta(self) -> dict:
        """What ``Track.meta["acquisition"]`` says: the key the graph tracked from (``handover``;
        None: never), the keys the filter gave it a factor at, the tracking starts it undid
        (``undone``), the ping it diverged at (``diverged``, None: never) and its seconds."""
        return {"handover": self.handover, "factors": list(self.factors), "undone": list(self.undone),
                "diverged": self.diverged, "seconds": self.seconds,
                **({"waiting": self.last_reason} if self.handover is None else {})}


def _tracker(nav: GraphNavigator) -> OnlineTerrain:
    """The navigator's tracking on soundings, which acquisition hands over to."""
    if nav.terrain is None:
        raise TangraphError("acquire = 'pmf' hands over to tracking on soundings: set terrain = 'soundings'")
    return nav.terrain


def _with_tide(state: PointMass, mean, cov) -> tuple[np.ndarray, np.ndarray]:
    """The density's moments over (north, east, tide): ``mean (2,)`` and ``cov (2, 2)`` its
    position's, with the tide's from every point's tide posterior (mean per point, the shared
    variance)."""
    mass = state.masses().ravel()
    tide = state.tide.ravel()
    tide_mean = float(mass @ tide)
    d_tide = tide - tide_mean
    mean3 = np.append(mean, tide_mean)
    cov3 = np.zeros((3, 3))
    cov3[:2, :2] = cov
    cov3[:2, 2] = cov3[2, :2] = (state.points() - mean).T @ (mass * d_tide)
    cov3[2, 2] = float(state.tide_var) + float(mass @ d_tide**2)
    return mean3, cov3


@dataclasses.dataclass(frozen=True)
class _Fix:
    position: np.ndarray
    covariance: np.ndarray


def _shape(state: PointMass, mean, cov) -> str:
    """Why the density is not one Gaussian-like part inside a grid laid on its moments ("" when
    it is)."""
    points = pf._grid(np.asarray(mean, float), pf._axes(np.asarray(cov, float)))
    density = np.sum([_sample(state, m, points)[0] for m in range(len(state.nodes))], axis=0)
    total = float(np.sum(density))
    if not total > 0:
        return "no density on its moments' grid"
    mass = density / total
    with np.errstate(divide="ignore"):
        n_parts, other = pf._parts(np.log(density), mass)
    if other >= pf.MODE_MASS:
        return f"multimodal: {n_parts} parts, {other:.0%} of the mass away from the main one"
    edge = pf._edge(mass)
    if edge > pf.EDGE_MASS:
        return f"{edge:.1%} of the density beyond {pf.GRID_SIGMAS:g} stds"
    return ""
