"""Lost and relocalisation: how the online navigator finds out that its belief is wrong.

The part of :class:`~tangraph.graph.GraphNavigator` that decides what to do with each fix
beyond the gate (``GraphConfig.lost_windows``, ``relocalise_fixes``, ``confirm_probability``):

- a fix close to the prediction is used at once; a surprising one (NIS between the
  ``confirm_probability`` quantile and the gate) waits for the next fix to agree with it;
- a fix is *trusted* once a later fix from a window that shares none of its pings agrees with
  it through the DR; the last trusted fix is where a lost episode starts;
- windows whose precise fix lies beyond the search (``OUTSIDE_SEARCH``) or beyond the gate are
  evidence; ``lost_windows`` of them since the last trusted fix make the navigator *lost*: it
  gives up the untrusted fixes (:meth:`Relocalisation._forget`, removed from iSAM2) and widens
  its belief by a *break* (on the start's prior when no fix was ever trusted, else on the
  odometry into the current key), so the searches grow fourfold and the covariance it reports
  says how little it knows;
- it relocalises on ``relocalise_fixes`` precise fixes from disjoint windows that agree with
  each other (the jump taken by a break sized to it, placed before the first of them), or ends
  the episode at once when a precise fix agrees with the belief it gave up (a false alarm);
- fixes refused only by the gate while tracking are weighed the same way: when enough agree,
  the prediction was the wrong one.

The pings from the last trusted fix to the end of an episode are flagged lost.
"""

from __future__ import annotations

import dataclasses
import logging
from typing import NamedTuple

import numpy as np

from tangraph.graph.calibration import to_world, world_jacobian
from tangraph.graph.factors import compose, gate_threshold, nis
from tangraph.graph.fixes import FixOutcome, FixStatus, LostEpisode
from tangraph.graph.keyposes import increments
from tangraph.matching import TapFix
from tangraph.sensors import rotation_matrix

__all__ = ["Relocalisation"]

log = logging.getLogger("tangraph.graph.online")  # the navigator's messages, one logger for them


def _gate(config) -> float:
    """The NIS limit of agreement between fixes: the gate's, at 0.999 when the gate is off."""
    return gate_threshold(config.gate_probability or 0.999)


def _widened(joint, variance: float) -> np.ndarray:
    """A joint covariance with ``variance`` (m^2) added to its position's (a break's)."""
    joint = np.array(joint, float)
    joint[0, 0] += variance
    joint[1, 1] += variance
    return joint


def _disjoint(candidates) -> int:
    """How many of ``candidates`` (in ping order) form a chain of windows that share no ping."""
    count, end = 0, -1
    for c in candidates:
        if c.first > end:
            count, end = count + 1, c.key
    return count


class _Candidate(NamedTuple):
    """A relocalisation candidate: the key, the first ping of its window, its fix (with the
    covariance the graph gives it), the predicted DR-frame pose of the key and the index of its
    record."""

    key: int
    first: int
    fix: TapFix
    pose: np.ndarray
    record: int


class Relocalisation:
    """The lost and relocalisation logic of :class:`~tangraph.graph.GraphNavigator` (a mixin:
    it works on the navigator's graph, iSAM2 smoother, fix records and pending factors)."""

    def _init_lost(self) -> None:
        """The state: no episode yet, no trusted fix, nothing held or pending."""
        self.lost = False
        self.episodes: list[LostEpisode] = []
        self._outside = 0  # windows saying the prediction is wrong since the last trusted fix
        self._last_accepted: int | None = None
        self._consensus: list[_Candidate] = []
        self._unconfirmed: list[_Candidate] = []  # fixes used but not yet trusted
        self._held: _Candidate | None = None  # an accepted fix waiting for a later one to agree
        self._start_factor = None  # the start's position prior as in iSAM2 (widened when found wrong)
        self._remove: list[int] = []  # iSAM2 factor indices to remove at the next update

    def _add_fix(self, k: int, pose, joint, fix: TapFix | None) -> float:
        """Make (or take) the fix of ping ``k`` (DR-frame ``pose`` and its ``joint`` covariance),
        judge it, add it to the new factors if accepted, and keep the lost state (see
        ``GraphConfig.lost_windows``). Returns the std (m) of the break to put on the odometry
        into key ``k`` (0 for none)."""
        if fix is None and not self._is_end[k]:
            return 0.0
        outcome = self._judge(k, pose, joint, fix, strict=self.lost)
        self.fixes.append(outcome.record)
        if not self.lost:
            if self._confirm(k, pose, joint, outcome):
                return 0.0
        extra = 0.0
        # a window that says the prediction is wrong (a vague one is a bad window)
        evidence = outcome.record.status.says_lost and self._precise(outcome, 1.0)
        if evidence:
            self._outside += 1  # the truth seems to lie beyond the search: widen it
            if self.config.lost_windows is not None and self._outside >= self.config.lost_windows and k > 0:
                self._outside = 0
                widening = self._widen(k, outcome.record.half_width)
                if widening > 0:
                    extra = self._break(widening)
                    joint = _widened(joint, widening**2)
                    outcome = self._judge(k, pose, joint, fix, strict=True)
                    self.fixes[-1] = outcome.record
        # relocalisation candidates: while lost, fixes that pass everything; while tracking, fixes
        # that only the gate refused (the prediction may be the wrong one); either way precise
        # ones
        usable = outcome.accepted if self.lost else (
            outcome.record.status is FixStatus.GATE and not outcome.fix.quality.multimodal)
        if not usable or self.config.lost_windows is None or not self._precise(outcome):
            return extra
        candidate = self._candidate(k, pose, outcome)
        if self.lost and not evidence and self._resumes(candidate, pose, joint):
            return extra
        if self.lost:
            self.fixes[-1] = dataclasses.replace(outcome.record, status=FixStatus.UNCONFIRMED,
                                                 detail="relocalisation candidate")
        if self._consensus and not self._agree(self._consensus[-1], candidate, joint):
            self._consensus = []
        self._consensus.append(candidate)
        if _disjoint(self._consensus) >= self.config.relocalise_fixes:
            extra = float(np.hypot(extra, self._relocalise(k, pose, joint)))
        return extra

    def _resumes(self, candidate: _Candidate, pose, joint) -> bool:
        """A lost navigator's candidate that agrees with the belief it gave up (the prediction
        without this episode's breaks, within the gate): the evidence was bad windows, not a wrong
        belief. The candidate is used, trusted, and the episode ends where it is."""
        widened = float(np.sum(np.square(self.episodes[-1].breaks)))
        world, cov = self._world(pose, _widened(joint, -widened))
        total = cov[:2, :2] + candidate.fix.covariance
        innovation = candidate.fix.position - world[:2]
        if np.linalg.eigvalsh(total).min() <= 0 or nis(innovation, total) > _gate(self.config):
            return False
        episode = self.episodes[-1]
        self._use(candidate, "the belief held", trusted=True)
        episode.end = candidate.key
        log.warning("graph: back on track at ping %d: the fix agrees with the belief held before ping %d",
                    candidate.key, episode.declared)
        self.lost, self._consensus = False, []
        return True

    def _precise(self, outcome: FixOutcome, share: float = 0.5) -> bool:
        """Whether a fix's largest std is within ``share / half_width_sigmas`` of its search's
        half-width: an eighth by default, as a relocalisation candidate must be (two vague fixes
        agree with anything); a quarter for a window whose best match on the search's edge is
        evidence of being lost (a vague one there is a window of bad pings)."""
        largest = float(np.sqrt(np.linalg.eigvalsh(outcome.fix.covariance).max()))
        return largest <= share * outcome.record.half_width / self.config.half_width_sigmas

    def _candidate(self, k: int, pose, outcome: FixOutcome) -> _Candidate:
        return _Candidate(k, int(outcome.fix.first), outcome.fix, np.asarray(pose, float).copy(),
                          len(self.fixes) - 1)

    def _confirm(self, k: int, pose, joint, outcome: FixOutcome) -> bool:
        """A tracking navigator's accepted fix: used at once when it is close to the prediction,
        held for the next fix to agree with when its NIS is above the ``confirm_probability``
        quantile (``GraphConfig``); a held fix is used once a later accepted fix agrees with it
        through the DR, dropped (``UNCONFIRMED``) when one disagrees or after two windows.
        Returns whether the outcome was accepted (used or held)."""
        held, agreed = self._held, False
        if held is not None and (outcome.accepted or k - held.key > 2 * self.config.spacing):
            agreed = outcome.accepted and self._agree(held, self._candidate(k, pose, outcome), joint)
            if agreed:
                self._use(held, f"confirmed by the fix at ping {k}")
            else:
                self._drop_held("the next fix did not agree" if outcome.accepted else "no fix came to agree")
            self._held = None  # used, or dropped
        if not outcome.accepted:
            return False
        limit = self.config.confirm_probability
        if limit is not None and outcome.record.nis > gate_threshold(limit) and (held is None or not agreed):
            self._held = self._candidate(k, pose, outcome)
            self.fixes[-1] = dataclasses.replace(outcome.record, status=FixStatus.UNCONFIRMED,
                                                 detail="held until a later fix agrees")
            return True
        self._use(self._candidate(k, pose, outcome), "")
        self._consensus = []  # the prediction held: the gate's refusals before were bad windows
        return True

    def _drop_held(self, why: str) -> None:
        """Give up the held fix (if any): ``UNCONFIRMED``, saying ``why``."""
        if self._held is not None:
            self.fixes[self._held.record] = dataclasses.replace(
                self.fixes[self._held.record], status=FixStatus.UNCONFIRMED,
                detail=f"held for confirmation; {why}")
            self._held = None

    def _use(self, candidate: _Candidate, detail: str, *, trusted: bool = False) -> None:
        """Add a fix to the graph and mark its record accepted. A fix is *trusted* (the last
        trusted fix is where a lost episode starts, and it clears the evidence of being lost)
        once a later accepted fix from a window that shares none of its pings agrees with it
        through the DR, or at once when ``trusted`` (fixes that agreed to relocalise); a
        multimodal fix never is (two places explain it). A fix whose key pose has left iSAM2's
        window (``isam_window``) is not added: it stays ``UNCONFIRMED``, for the batch smoother."""
        fix = candidate.fix
        record = self.fixes[candidate.record]
        key = candidate.key
        if not (self.isam.getLinearizationPoint().exists(key) or self._new_values.exists(key)):
            self.fixes[candidate.record] = dataclasses.replace(  # left to the batch smoother
                record, status=FixStatus.UNCONFIRMED, detail="its key has left iSAM2's window")
            return
        self._new_factors.add(self.graph.add_position_fix(candidate.key, fix.position, fix.covariance,
                                                          self._fix_factor(candidate.key, fix)))
        self.fixes[candidate.record] = dataclasses.replace(record, status=FixStatus.ACCEPTED,
                                                           detail=detail or record.detail)
        if fix.quality.multimodal:
            return
        confirmed = [u.key for u in self._unconfirmed
                     if u.key < candidate.first and self._agree(u, candidate, self._key_joint)]
        if trusted or confirmed:
            last = candidate.key if trusted else max(confirmed)
            self._last_accepted = max(last, self._last_accepted or 0)
            self._outside, self._consensus = 0, []
            self._unconfirmed = [u for u in self._unconfirmed if u.key > last]
        if not trusted:
            self._unconfirmed.append(candidate)

    def _break(self, std: float) -> float:
        """Widen the belief by ``std`` (m): on the start's position prior when the episode goes
        back to the first ping (no fix was ever trusted: the start prior is the belief given up,
        and widening it keeps the constant DR errors from bending to reconcile it with the
        fixes), else on the odometry into the current key. Returns the odometry's break std."""
        if self.episodes[-1].start == 0 and self._widen_start(std):
            return 0.0
        return std

    def _widen_start(self, std: float) -> bool:
        """Replace the start's position prior in iSAM2 by one wider by ``std``
        (:meth:`~tangraph.graph.PoseGraph.widen_start`); False when the first pose has been
        marginalised."""
        index = self._isam_index(self._start_factor)
        if index is None or not self.isam.getLinearizationPoint().exists(0):
            return False
        self._remove.append(index)
        self._start_factor = self.graph.widen_start(std)
        self._new_factors.add(self._start_factor)
        return True

    def _widen(self, k: int, half_width: float) -> float:
        """Start (or go on with) a lost episode at key ``k`` and return by how much (std, m) to
        widen the belief: the search's half-width (the truth lies beyond it), up to what the
        widest search can still see (0 once there)."""
        config = self.config
        if not self.lost:
            self.lost = True
            self._drop_held("the navigator was lost before a fix agreed")  # searched around the old belief
            start = 0 if self._last_accepted is None else self._last_accepted
            self.episodes.append(LostEpisode(start=start, declared=k))
            self._forget(start, k)  # what was built on the belief now given up
            log.warning("graph: lost at ping %d (the best matches lie beyond the search since ping %d)",
                        k, start)
        episode = self.episodes[-1]
        cap = config.max_half_width_cells * float(min(self.bathymetry.cell_size)) / config.half_width_sigmas
        widened = float(np.sqrt(np.sum(np.square(episode.breaks))))
        if widened >= cap:
            return 0.0
        episode.breaks.append(min(float(half_width), float(np.sqrt(cap**2 - widened**2))))
        self._consensus = []  # candidates behind a break are tied to the old belief
        return episode.breaks[-1]

    def _relocalise(self, k: int, pose, joint) -> float:
        """Enough agreeing candidates: the belief since the last trusted fix was wrong. Give up
        what was built on it (the weak fixes accepted since, see :meth:`_forget`), let the
        candidates move the track by a break as large as their distance from the prediction
        (on the start's prior when no fix was ever trusted, else on the odometry into the first
        candidate's key, so the jump is the break's and not the constant DR errors'), and add
        them all. Where that odometry factor has left iSAM2's window, the break goes into key
        ``k`` and only the newest is added (the others stay ``UNCONFIRMED`` for the smoother).
        Returns the std of a break into key ``k`` (0 for none)."""
        taken = list(self._consensus)
        world, _ = self._world(pose, joint)
        cell = float(min(self.bathymetry.cell_size))
        jump = max(float(np.hypot(*(taken[-1].fix.position - world[:2]))), cell)
        if self.lost:
            episode = self.episodes[-1]
        else:
            start = 0 if self._last_accepted is None else self._last_accepted
            episode = LostEpisode(start=start, declared=taken[0].key)
            self.episodes.append(episode)
        episode.breaks.append(jump)
        self._forget(episode.start, k)
        extra = 0.0
        if not ((episode.start == 0 and self._widen_start(jump)) or self._break_into(taken[0].key, jump)):
            taken, extra = taken[-1:], jump
        for candidate in taken:
            self._use(candidate, "relocalised", trusted=True)
        episode.end = k
        log.warning("graph: relocalised at ping %d (lost since ping %d)", k, episode.start)
        self._drop_held("the navigator relocalised before a fix agreed")
        self.lost = False
        return extra

    def _isam_index(self, factor) -> int | None:
        """The index of ``factor`` in iSAM2's graph (None if it is not there any more)."""
        factors = self.smoother.getFactors()
        return next((i for i in range(factors.size()) if factors.at(i) is factor), None)

    def _forget(self, start: int, k: int) -> None:
        """Remove from iSAM2 the fixes accepted after ping ``start`` (the last trusted fix) and
        before ``k``: none of them was confirmed, and they were searched around the belief the
        navigator now gives up. Their records become ``UNCONFIRMED`` (the batch smoother weighs
        them again)."""
        graph = self.graph
        keep = []
        for n, (key, _, _) in enumerate(graph.fixes):
            index = self._isam_index(graph._factors["fix"][n]) if start < key < k else None
            if index is None:
                keep.append(n)
                continue
            self._remove.append(index)
            at = next(i for i, r in enumerate(self.fixes) if r.index == key and r.accepted)
            self.fixes[at] = dataclasses.replace(
                self.fixes[at], status=FixStatus.UNCONFIRMED,
                detail=f"given up at ping {k}: the navigator found its belief wrong")
        graph.fixes = [graph.fixes[n] for n in keep]
        graph._factors["fix"] = [graph._factors["fix"][n] for n in keep]
        self._unconfirmed = [u for u in self._unconfirmed if not start < u.key < k]

    def _break_into(self, key: int, std: float) -> bool:
        """Widen by ``std`` the odometry factor into ``key`` in iSAM2 (a break after the fact);
        False when it has left iSAM2's window."""
        graph = self.graph
        n = next((n for n, odo in enumerate(graph.odometry) if odo[1] == key), None)
        index = None if n is None else self._isam_index(graph._factors["odometry"][n])
        if index is None or key == 0:
            return False
        total = float(np.hypot(graph.breaks.get(key, 0.0), std))
        graph.breaks[key] = total
        graph._factors["odometry"][n] = graph._odometry_factor(*graph.odometry[n], total)
        self._remove.append(index)
        self._new_factors.add(graph._factors["odometry"][n])
        return True

    def _agree(self, a: _Candidate, b: _Candidate, joint) -> bool:
        """Whether candidate ``b`` agrees with the earlier ``a`` through the DR between them: the
        NIS of the difference of their fixes against the DR's world displacement from ``a``'s
        predicted pose (white DR noise of the increment, ``a``'s heading and the calibration's
        covariance from ``joint``) is within the gate. ``b``'s own prediction is not used: it
        holds the corrections of the fixes used since ``a``, ``a``'s own among them."""
        delta, q = increments(self.white, self.survey.time, self.survey.dr_pose, [a.key], [b.key])
        positions = np.array([a.pose, compose(a.pose, delta[0])])
        world = to_world(positions, self.calibration, self.origin)
        jac = world_jacobian(positions, self.calibration, self.origin)
        rot = jac[1, :2, :2] @ rotation_matrix(a.pose[2])  # a's frame to the world
        turn = jac[1, :2, :2] @ rotation_matrix(a.pose[2] + np.pi / 2) @ delta[0, :2]  # d / d heading
        shape = jac[1, :2, 3:] - jac[0, :2, 3:]
        cov = (a.fix.covariance + b.fix.covariance + rot @ q[0, :2, :2] @ rot.T
               + shape @ joint[3:, 3:] @ shape.T + np.outer(turn, turn) * joint[2, 2])
        error = b.fix.position - a.fix.position - (world[1, :2] - world[0, :2])
        return nis(error, cov) <= _gate(self.config)
