"""Every sounding in the online graph once it has found the vehicle: a terrain factor per key.

With ``GraphConfig.online.terrain = "soundings"`` the online navigator works in two modes, as
terrain-aided navigation systems have since SITAN: TAP windows and the fix policy *acquire* the
vehicle, and once it is found the navigator *tracks* it on every sounding.

**When it tracks.** The fix policy is not lost and has used a unimodal fix (a fix used as one of
several places would lead the linearised soundings into its basin), and the map is near its
tangent plane over the belief: over each new ping's 2-sigma position ellipse (the key's belief
carried to the ping by the DR) the map's depth under its footprints departs from its
linearisation by less than the soundings' noise (:func:`_nonlinearity`), so the soundings
linearised there hold over the belief. (Started, the update that adds the first factor is
iterated: ``START_ITERATIONS``.)

**The factor.** At each key step the soundings of the pings hung from the previous key (its own
ping and those before the new key, less any ping a window took) enter iSAM2 as one factor on
that key pose, the calibration and the tide. This is the batch smoother's terrain model
(:mod:`tangraph.graph.terrain_factors`): every sounding's residual against the map's depth at its
footprint, with the row-sum variance of the map's error read where the prediction puts it
(:meth:`OnlineTerrain.placed`; the dead reckoning, metres to tens of metres off, would put a
sounding of a filled gap between the map's lines on a line), judged at the prediction and
linearised at the mode of the key's belief given them (:func:`_mode`: an iterated Kalman
update's point), with the white DR noise between the key and each ping integrated out exactly:
all soundings of a ping share its noise, and each ping that of the pings before it
(:func:`~tangraph.graph.terrain_factors.chain_information`; counted as each sounding's own, a
ping's soundings told its position as many times over as it has soundings). The factor is
linear (a :class:`gtsam.LinearContainerFactor`): the tangent-plane test above is what makes the
linearisation hold over the belief, and iSAM2 updates it without calling back into Python. The
tide is a variable of the graph (its prior the model's), so the soundings' common offset is
learnt, not taken as position.

**Little information where the terrain does not rise above the map's noise.** Each sounding's
likelihood is raised to its information exponent, the filters' MBARI weighting linearised
(:meth:`OnlineTerrain._exponents`): a belief narrower than the map's error lets the terrain
under it vary by less than that error, and soundings that converge it further would follow the
map's noise. (On a perfect map every exponent is 1.)

**The soundings judged** as innovations of the prediction, once: each at ``SOUNDING_GATE`` sigma
of the prediction's position and tide uncertainty, each ping's together at
``terrain_factors.PING_PROBABILITY`` (:func:`~tangraph.graph.terrain_factors.gate`: a ping that
fits the map nowhere near the prediction, a fault of its depths or its footprints, is left
out), and the key's together as a fix is (:func:`_innovation`, with the DR noise and the tide's
drift their pings share, as in the factor): when the shift of the footprints and the tide they
pull for is beyond the fixes' gate, none is used. A block of pings whose
footprints are all misplaced the same way fits the map ping by ping nearly as well as the truth
does, and only together tells.

**No sounding counted twice.** No window is made over pings a factor holds, and a factor starts
after the pings any window took. While tracking, the windows are searched and judged as checks
only (``FixStatus.CHECKED``).

**When tracking ends**, the windows, their fixes and the fix policy's lost test take over, and
tracking waits for a new unimodal fix the policy uses:

- a check says the prediction is wrong: beyond the gate, its best match at the search's edge
  (and its calibrated region without the prediction), or precise and surprising
  ``CHECK_WINDOWS`` times in a row (:meth:`OnlineTerrain.window`). A
  belief the linearised soundings have led into a wrong basin still fits them; the check finds
  it. The policy then takes that window (its pings are counted twice there);
- the map's departure from its tangent plane grows beyond ``NONLINEAR_STOP`` times the noise (the
  terrain told too little to keep the belief narrow for it; pings with no sounding on the map
  tell nothing and do not end it: the DR carries the belief over them);
- more than half of the pings of ``MISFIT_KEYS`` keys in a row fail the ping test.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING

import gtsam
import numpy as np
from scipy import stats

from tangraph.fix_records import FixStatus
from tangraph.geometry import gate_threshold, rotation_matrix
from tangraph.graph import online_tide
from tangraph.graph.calibration import CALIBRATION, world_covariance
from tangraph.graph.factors import compose, propagate_joint
from tangraph.graph.lost import _isam_index
from tangraph.graph.terrain_factors import (
    NONLINEAR_SIGMAS,
    PingTerrain,
    _evaluate,
    chain_information,
    footprints,
    gate,
    information_factor,
    tangent_departure,
)
from tangraph.sensors import (
    MapError,
    map_error,
    placed_map_variances,
    sounding_map_counts,
    sounding_variances,
)

if TYPE_CHECKING:
    from tangraph.graph.online import GraphNavigator

__all__ = ["CHECK_PROBABILITY", "CHECK_WINDOWS", "MIN_EXPONENT", "MISFIT_KEYS", "NONLINEAR_SIGMAS",
           "NONLINEAR_STOP", "SOUNDING_GATE", "START_ITERATIONS", "OnlineTerrain", "tangent_departure"]

#: Tracking ends when the map's departure from its tangent plane over the belief
#: (:func:`_nonlinearity`) grows beyond this many times the soundings' variance (it starts at 1).
NONLINEAR_STOP = 4.0
#: Tracking ends when more than half of the pings of this many keys in a row fail the ping test.
MISFIT_KEYS = 2
#: Tracking ends after this many windows in a row whose check fix (used or not) is surprising to
#: the prediction: its NIS beyond the ``chi2(2)`` quantile of ``CHECK_PROBABILITY``
CHECK_WINDOWS = 2
CHECK_PROBABILITY = 0.9
_SURPRISE = float(stats.chi2.ppf(CHECK_PROBABILITY, 2))
#: A sounding beyond this many sigma of its innovation is left out (two-sided 0.999 of a normal).
SOUNDING_GATE = 3.29
#: Further iSAM2 updates (Gauss-Newton steps: one per update) when tracking starts (and when the
#: point-mass filter gives its first factor): the graph's nonlinear factors (the odometry through
#: the calibration, the filter's) are relinearised from a belief that may be metres off, far for
#: one step (the tracking factors themselves are linear)
START_ITERATIONS = 5
#: A sounding whose information exponent (:meth:`OnlineTerrain._exponents`) is below this tells
#: nothing here and is left out of its factor
MIN_EXPONENT = 1e-3
#: Gauss-Newton iterations of the output between keys (:meth:`OnlineTerrain.filtered`)
FILTERED_ITERATIONS = 3
_USED = (FixStatus.ACCEPTED, FixStatus.CONFIRMED)


@dataclasses.dataclass
class OnlineTerrain:
    """The tracking state of one online run: every sounding's terrain variance ``variance (K,
    B)``, whether it ``tracking`` now, the first ping no factor holds yet (``next_ping``: a window
    may start there) and no window holds (``free_ping``: a factor may start there),
    the share of failed pings of the last keys, and counts for the track's meta."""

    variance: np.ndarray
    tracking: bool = False
    next_ping: int = 0
    free_ping: int = 0
    surprises: int = 0
    failed: list[float] = dataclasses.field(default_factory=list)
    factors: int = 0
    pings: int = 0
    soundings: int = 0
    episodes: list[list[int]] = dataclasses.field(default_factory=list)
    found: bool = False  # the fix policy has used a unimodal fix (since tracking last ended)
    counts: np.ndarray | None = None  # (K, B, F) how many soundings share each field of its map error
    error: MapError | None = None  # the map's error, read where the prediction puts the soundings
    _judged: object = None  # the navigator's latest window outcome, looked at for that
    _first: tuple = (None, 0, 0)  # the factor of the latest episode's first key, its pings and soundings

    @classmethod
    def of(cls, nav: GraphNavigator) -> OnlineTerrain:
        counts = sounding_map_counts(nav.survey, nav.bathymetry, nav.model)
        error = None if counts is None else map_error(nav.bathymetry, nav.model)
        return cls(sounding_variances(nav.survey, nav.bathymetry, nav.model), counts=counts, error=error)

    def placed(self, nav: GraphNavigator, key: int, pings) -> tuple[PingTerrain, np.ndarray | None]:
        """The ``pings`` hung from key ``key``, each sounding's variance read where the prediction
        puts it (:func:`tangraph.sensors.placed_map_variances`; a filter's, where its cloud does),
        not at its dead-reckoned footprint, and the map's own error variance there ``(K, B)``."""
        terrain = _terrain(nav, key, pings, self.variance[pings])
        if self.counts is None or self.error is None:
            return terrain, None  # a perfect map
        north, east = footprints(terrain, nav.bathymetry, nav._key_pose[None], nav.calibration)
        shared, own = placed_map_variances(self.error, self.counts[pings], north, east)
        noise = float(nav.model.sounding_std) ** 2
        variance = np.where(np.isfinite(terrain.variance), noise + shared, np.nan)
        return dataclasses.replace(terrain, variance=variance), own

    def meta(self) -> dict:
        """What ``Track.meta["terrain"]`` says: factors, pings and soundings used, and the
        tracking episodes ``[first key, last key]``."""
        return {"factors": self.factors, "pings": self.pings, "soundings": self.soundings,
                "episodes": [list(e) for e in self.episodes]}

    def window_allowed(self, nav: GraphNavigator, k: int) -> bool:
        """Whether the window ending at ping ``k`` may be made: not while tracking, nor over
        pings a terrain factor holds."""
        return not self.tracking and nav.window_first.get(k, k) >= self.next_ping

    def window_taken(self, k: int) -> None:
        """The window ending at ping ``k`` was made: a later factor starts after it."""
        self.free_ping = max(self.free_ping, k + 1)

    def window(self, nav: GraphNavigator, k: int, pose, joint) -> bool:
        """Whether the fix policy takes the window ending at ping ``k`` (DR-frame ``pose`` and
        ``joint`` covariance predicted). While tracking it is searched and judged as a check
        only (its pings are in the factors; recorded as ``CHECKED``), unless it says the
        prediction is wrong: beyond the gate or its best match at the search's edge, or precise
        and surprising (NIS beyond the ``chi2(2)`` quantile ``CHECK_PROBABILITY``) as the
        ``CHECK_WINDOWS - 1`` checks before it were. Then tracking ends, the policy takes this
        window (the one place its pings count twice: where the factors led the belief astray).
        Otherwise, see :meth:`window_allowed`. (A check whose best match lies at the search's
        edge but whose calibrated region holds the prediction does not end tracking.)"""
        if not nav._is_end[k]:
            return True
        if not self.tracking:
            allowed = self.window_allowed(nav, k)
            if allowed:
                self.window_taken(k)
            return allowed
        outcome = nav._judge(k, pose, joint, None)
        record = outcome.record
        self.surprises = self.surprises + 1 if record.accepted and record.nis > _SURPRISE else 0
        # a best match on the search's edge whose region still holds the prediction does not
        # contradict it
        says_lost = record.status.says_lost and not (
            record.status is FixStatus.OUTSIDE_SEARCH and outcome.fix is not None
            and outcome.fix.quality.holds_centre)
        if says_lost or self.surprises >= CHECK_WINDOWS:
            self._stop()
            self.window_taken(k)
            return True
        nav.fixes.append(dataclasses.replace(record, status=FixStatus.CHECKED,
                                             detail=f"{record.status.value}: {record.detail}".rstrip(": ")))
        return False

    def key_step(self, nav: GraphNavigator, prev: int, k: int) -> None:
        """At the key step of ping ``k`` (``prev`` the latest key, its estimate current): decide
        whether the navigator tracks, and if so add the factor of the pings hung from ``prev``
        to the navigator's new factors."""
        judged = nav._last_outcome
        if judged is not None and judged is not self._judged:  # the policy's latest window
            self._judged = judged
            fix = judged.fix
            if judged.record.status in _USED and fix is not None and not fix.quality.multimodal:
                self.found = True
        first = max(prev, self.free_ping)
        tide_known = nav.tide or nav.model.tide_variance == 0
        if nav.state.lost or not (self.found and tide_known) or first >= k:
            self._stop()
            return
        pings = np.arange(first, k)
        terrain, own = self.placed(nav, prev, pings)
        bent = _nonlinearity(nav, terrain, prev, pings)
        # (pings with no sounding on the map tell nothing: tracking carries the DR over them)
        if not (bent <= (NONLINEAR_STOP if self.tracking else 1.0) or (np.isnan(bent) and self.tracking)):
            self._stop()
            return
        if not self.tracking:
            self.tracking = True
            self.episodes.append([prev, prev])
            nav._extra_iterations = START_ITERATIONS
        self.next_ping = self.free_ping = max(self.free_ping, k)
        counts = (self.pings, self.soundings)
        factor, failed = self._factor(nav, prev, pings, terrain, own)
        if self.episodes[-1][1] == prev:  # the episode's first factor: what undoing it takes back
            self._first = (factor, self.pings - counts[0], self.soundings - counts[1])
        self.failed = [*self.failed[-(MISFIT_KEYS - 1):], failed] if MISFIT_KEYS > 1 else [failed]
        if factor is not None:
            nav._new_factors.add(factor)
            self.factors += 1
        self.episodes[-1][1] = k
        if len(self.failed) == MISFIT_KEYS and min(self.failed) > 0.5:
            self._stop()

    def handed_over(self, k: int) -> None:
        """A point-mass filter gave the graph its information at key ``k``
        (:mod:`tangraph.graph.acquisition`): the vehicle is found (the next key step may track),
        and the pings up to ``k`` are the filter's."""
        self.found = True
        self.next_ping = self.free_ping = k + 1

    def filtered(self, nav: GraphNavigator, k: int) -> tuple[np.ndarray, np.ndarray] | None:
        """While tracking, the world pose and covariance of ping ``k`` (not a key) given the
        soundings since the latest key too (None when not tracking or none is used): the output
        of a navigator uses what it has heard up to now, though these soundings enter iSAM2 only
        at the next key. The prediction from the latest key is moved by the mode of a common
        shift of the key's world position (and the tide when held) given the soundings of the
        pings no factor holds yet, gated as the factor's are (:func:`_mode`), and the covariance
        of ping ``k`` less what the key's became more certain."""
        first = max(nav._key_of, self.free_ping)
        if not self.tracking or first > k:
            return None
        pings = np.arange(first, k + 1)
        terrain, own = self.placed(nav, nav._key_of, pings)
        tide, tide_var = (nav._tide_mean, float(nav._tide_joint[5, 5])) if nav.tide else (nav.model.tide, 0.0)
        key = nav._key_pose[None]
        key_cov = nav._world(nav._key_pose, nav._key_joint)[1][:2, :2]
        prior = _ping_covariances(nav, nav._key_of, pings)
        drift = online_tide.ping_variance(nav, nav._key_of, pings)
        used = gate(terrain, nav.bathymetry, key, nav.calibration, tide, SOUNDING_GATE, prior=prior,
                    offset_variance=tide_var + (0.0 if drift is None else drift))
        if not used.any():
            return None
        residual, _, _, grad, _, _, noise = _evaluate(terrain, nav.bathymetry, key, nav.calibration, tide,
                                                      jacobian=False, noise=True)
        exponent = self._exponents(own, grad, prior)  # weighed as judged, at the prediction
        used &= exponent > MIN_EXPONENT
        if not used.any():
            return None
        shift, posterior = _mode(nav, terrain, key, tide, tide_var, key_cov, used, exponent, drift,
                                 (residual, grad, noise))
        pose, cov = nav.predicted(k)
        pose[:2] += shift[:2]
        cov[:2, :2] -= key_cov - posterior[:2, :2]
        return pose, cov

    def undo_start(self, nav: GraphNavigator) -> None:
        """Undo the tracking episode that has just started (a check found its first update wrong,
        :meth:`tangraph.graph.acquisition.Acquisition.vet`): its factor is taken out of iSAM2 at
        the next update, its counts and episode forgotten, tracking stopped."""
        factor, pings, soundings = self._first
        index = None if factor is None else _isam_index(nav, factor)
        if index is not None:
            nav._remove.append(index)
            self.factors -= 1
        self.pings -= pings
        self.soundings -= soundings
        self.episodes.pop()
        self._stop()

    def _stop(self) -> None:
        """End tracking (if it was on): it waits for a unimodal fix the policy uses after this."""
        if self.tracking:
            self.tracking = self.found = False
            self.failed = []
            self.surprises = 0

    def _factor(self, nav: GraphNavigator, prev: int, pings: np.ndarray, terrain: PingTerrain, own):
        """The factor of the ``pings`` hung from key ``prev`` (None when no sounding passes)
        and the share of those pings with soundings on the map that failed."""
        tide, tide_var = _tide_belief(nav, prev)
        key = nav._key_pose[None]
        prior = _ping_covariances(nav, prev, pings)
        drift = online_tide.ping_variance(nav, prev, pings)
        used = gate(terrain, nav.bathymetry, key, nav.calibration, tide, SOUNDING_GATE, prior=prior,
                    offset_variance=tide_var + (0.0 if drift is None else drift))
        # judged at the prediction (the Jacobians are taken at the mode, where the factor is made)
        residual, _, _, grad, _, _, noise = _evaluate(terrain, nav.bathymetry, key, nav.calibration, tide,
                                                      jacobian=False, noise=True)
        seen = np.any(np.isfinite(residual), axis=1)
        failed = float(np.mean(~np.any(used, axis=1)[seen])) if seen.any() else 0.0
        if used.any():
            gate_nis = gate_threshold(nav.config.fixes.gate_probability or 0.999, 2 + int(tide_var > 0))
            if _innovation(terrain, used, residual, grad, noise, drift, prior[0], tide_var) > gate_nis:
                used[:] = False  # the soundings together pull the belief beyond its gate
                failed = 1.0
        exponent = self._exponents(own, grad, prior)
        used &= exponent > MIN_EXPONENT
        if not used.any():
            return None, failed
        # made at the mode of the key's belief given them (at the prediction it led back there)
        key_cov = nav._world(nav._key_pose, nav._key_joint)[1][:2, :2]
        shift, _ = _mode(nav, terrain, key, tide, tide_var, key_cov, used, exponent, drift,
                         (residual, grad, noise))
        pose = nav._key_pose.copy()
        pose[:2] += (1.0 + nav.calibration[0]) * rotation_matrix(nav.calibration[1]) @ shift[:2] \
            if terrain.calibrated else shift[:2]  # the world shift in the DR frame
        tide = tide + (shift[2] if shift.size == 3 else 0.0)
        residual, jac, _, _, _, _, noise = _evaluate(terrain, nav.bathymetry, pose[None], nav.calibration,
                                                     tide, noise=True)
        used &= np.isfinite(residual)
        self.pings += int(np.any(used, axis=1).sum())
        self.soundings += int(used.sum())
        keys = [int(prev)] + ([CALIBRATION] if terrain.calibrated else []) \
            + ([online_tide.of_key(nav, prev)] if terrain.estimates_tide else [])
        info, gradient = _information(terrain, used, jac, noise, residual, exponent, drift)
        factor = information_factor(info, gradient, keys)
        if factor is None:
            return None, failed
        at = gtsam.Values()
        at.insert(keys[0], gtsam.Pose2(*pose))
        if terrain.calibrated:
            at.insert(CALIBRATION, np.asarray(nav.calibration, float))
        if terrain.estimates_tide:
            at.insert(keys[-1], np.array([tide]))
        return gtsam.LinearContainerFactor(factor, at), failed

    @staticmethod
    def _exponents(map_variance, grad, position_cov) -> np.ndarray:
        """The information exponents ``(K, B)`` of soundings (the filters' MBARI
        weighting, :func:`tangraph.sensors.information_exponent`, linearised): with ``D^2`` the
        spread of the depths the belief predicts for a sounding, ``g^T P g`` (``g`` the map's
        gradient under it, ``P`` its ping's position covariance ``position_cov (K, 2, 2)``),
        less what the map's noise ``s^2`` alone would spread, ``D^2 / (D^2 + 2 s^2)``: 1 on a
        perfect map, near 0 where the belief is too narrow for the terrain under it to rise
        above the map's noise."""
        if map_variance is None:
            return np.ones(grad.shape[:2])
        s2 = np.nan_to_num(map_variance)
        spread = np.maximum(np.einsum("kbi,kij,kbj->kb", grad, position_cov, grad) - s2, 0.0)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(s2 > 0, spread / (spread + 2.0 * s2), 1.0)


def _information(terrain: PingTerrain, used, a, noise, residual, exponent,
                 drift=None) -> tuple[np.ndarray, np.ndarray]:
    """The information and gradient of the soundings ``used`` on the parameters whose derivatives
    are ``a (K, B, P)``, each sounding weighed by its exponent as it was judged, with the DR
    noise since the key that their pings share integrated out
    (:func:`~tangraph.graph.terrain_factors.chain_information`), and the tide's drift since the
    key (``drift (K,)``, its variance at each ping: :func:`tangraph.graph.online_tide.ping_variance`)
    as a fourth noise of that walk, which moves every sounding of a ping alike."""
    ok = used & np.isfinite(residual) & np.all(np.isfinite(a), axis=-1)
    cov = terrain.increment_cov
    if drift is not None:
        noise = np.concatenate([noise, np.full((*noise.shape[:2], 1), -1.0)], axis=-1)  # d r / d tide
        walk = np.zeros((len(cov), 4, 4))
        walk[:, :3, :3], walk[:, 3, 3] = cov, drift
        cov = walk
    mask = ok[..., None]
    return chain_information(np.where(mask, a, 0.0), np.where(mask, noise, 0.0), np.where(ok, residual, 0.0),
                             np.where(ok, exponent / terrain.variance, 0.0), cov)


def _mode(nav: GraphNavigator, terrain: PingTerrain, key, tide: float, tide_var: float, key_cov, used,
          exponent, drift, first) -> tuple[np.ndarray, np.ndarray]:
    """The mode of a common shift of the key's world position (and of the tide when
    ``tide_var > 0``) given the soundings ``used`` (weighed by their ``exponent``), under the
    key's world position covariance ``key_cov (2, 2)``: ``FILTERED_ITERATIONS`` Gauss-Newton
    steps from the prediction (``first``: the residuals, map gradients and noise derivatives
    there), ``(P^-1 + G^T C^-1 G)^-1 G^T C^-1 r`` relinearised at the shifted footprints (``G``
    the map's gradients, and ones; ``C`` the soundings' covariance with the DR noise since the key
    that their pings share, :func:`_information`). Returns the shift and its covariance."""
    n = 3 if tide_var > 0 else 2
    information = np.zeros((n, n))
    information[:2, :2] = np.linalg.inv(key_cov)
    if n == 3:
        information[2, 2] = 1.0 / tide_var
    shift = np.zeros(n)
    residual, grad, noise = first
    for step in range(FILTERED_ITERATIONS):
        if step:
            residual, _, _, grad, _, _, noise = _evaluate(
                terrain, nav.bathymetry, key, nav.calibration, tide, jacobian=False,
                offset=shift[2] if n == 3 else None, map_offset=shift[:2], noise=True)
        g = grad if n == 2 else np.concatenate([grad, np.ones((*grad.shape[:2], 1))], axis=-1)
        info, gradient = _information(terrain, used, -g, noise, residual, exponent, drift)
        posterior = np.linalg.inv(information + info)
        shift = shift - posterior @ (gradient + information @ shift)
    return shift, posterior


def _innovation(terrain: PingTerrain, used, residual, grad, noise, drift, position_cov,
                tide_var: float) -> float:
    """The NIS of the shift of the footprints (and of the tide) that the soundings ``used`` pull
    for (their residuals ``(K, B)`` on the map gradients ``grad (K, B, 2)``, with the DR noise
    since the key their pings share and the tide's drift integrated out as in the factor:
    :func:`_information`, unweighed) against the prediction's position covariance ``(2, 2)``
    and tide variance: with ``H`` and ``b`` the soundings' information and gradient on the shift,
    ``b^T (H P H + H)^+ b``, chi-square with as many degrees of freedom as ``H`` has rank under
    the prediction. The fix gate of a key's soundings taken together: a block of pings whose
    footprints are all misplaced the same way fits the map, ping by ping, nearly as well as the
    truth does, and only together tell."""
    g = grad if tide_var <= 0 else np.concatenate([grad, np.ones((*grad.shape[:2], 1))], axis=-1)
    h, b = _information(terrain, used, -g, noise, residual, np.ones(residual.shape), drift)
    prior = np.zeros((g.shape[-1], g.shape[-1]))
    prior[:2, :2] = position_cov
    if tide_var > 0:
        prior[2, 2] = tide_var
    return float(b @ np.linalg.pinv(h @ prior @ h + h, hermitian=True) @ b)


def _nonlinearity(nav: GraphNavigator, terrain: PingTerrain, prev: int, pings: np.ndarray) -> float:
    """How far the map departs from its tangent plane over the belief, against the soundings'
    noise (:func:`tangent_departure`), at the footprints of the prediction and over each ping's
    world position covariance (the key ``prev``'s carried by the DR to the ping: the belief the
    ping's soundings are linearised over)."""
    north, east = footprints(terrain, nav.bathymetry, nav._key_pose[None], nav.calibration)
    covariances = _ping_covariances(nav, prev, pings)
    return tangent_departure(nav.bathymetry, north, east, terrain.variance, covariances)


def _ping_covariances(nav: GraphNavigator, prev: int, pings: np.ndarray) -> np.ndarray:
    """The world position covariance ``(K, 2, 2)`` of each of the ``pings`` hung from the latest
    key ``prev`` (its own ping: the key's)."""
    pings = np.asarray(pings, np.int64)
    key = np.broadcast_to(nav._key_pose, (pings.size, 3))  # nav.predicted, all at once
    pose = compose(key, nav._delta[pings])
    joints = np.broadcast_to(nav._key_joint, (pings.size, *np.shape(nav._key_joint)))
    joint = propagate_joint(key, joints, nav._delta[pings], nav._delta_cov[pings])
    joint[pings == prev] = nav._key_joint
    pose[pings == prev] = nav._key_pose
    return world_covariance(pose, joint, nav.calibration, nav.origin)[:, :2, :2]


def _tide_belief(nav: GraphNavigator, key: int) -> tuple[float, float]:
    """The tide's estimate and variance at key pose ``key`` now: the graph's when it holds the
    tide, else the model's (known)."""
    if not nav.tide:
        return float(nav.model.tide), 0.0
    tide = online_tide.of_key(nav, key)
    return float(nav.isam.calculateEstimateVector(tide)[0]), float(nav.isam.marginalCovariance(tide)[0, 0])


def _terrain(nav: GraphNavigator, prev: int, pings: np.ndarray, variance: np.ndarray) -> PingTerrain:
    """The pings hung from key ``prev`` (the key's own ping with no increment)."""
    increment = nav._delta[pings].copy()
    increment_cov = nav._delta_cov[pings].copy()
    own = pings == prev
    increment[own], increment_cov[own] = 0.0, 0.0
    s = nav.survey
    offsets = np.stack([s.beam_forward[pings], s.beam_starboard[pings]], axis=-1).astype(float)
    tide_std = float(np.sqrt(nav.model.tide_variance)) if nav.tide else 0.0  # > 0: a tide variable
    return PingTerrain(np.array([prev]), np.zeros(pings.size, np.int64), increment, increment_cov, offsets,
                       np.asarray(s.beam_depth[pings], float), variance, nav.origin.copy(),
                       nav.graph.calibrated, float(nav.model.tide), tide_std)
