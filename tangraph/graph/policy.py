"""The online fix policy: what the navigator does with each TAP window, decided apart from the graph.

:meth:`FixPolicy.decide` is a pure function: from the policy's state (:class:`PolicyState`, an
immutable value) and one window's outcome (:class:`Window`) it returns the next state and the
actions (:class:`Use`, :class:`Mark`, :class:`GiveUp`, :class:`Widen`, :class:`Relocalise`) that
the navigator executes on its graph and iSAM2 (:mod:`tangraph.graph.lost`). It uses no GTSAM
object: what only the navigator knows (whether two fixes agree through the dead reckoning, how a
fix sits against the belief given up, whether a key pose is still in iSAM2's window) comes with
the window. The rules (``GraphConfig.online.lost_windows``, ``relocalise_fixes``, ``confirm_probability``):

- a fix close to the prediction is used at once; a surprising one (NIS between the
  ``confirm_probability`` quantile and the gate) is ``HELD`` until a later accepted fix, as
  surprising to the prediction, agrees with it through the DR (it is used then), and is
  ``UNCONFIRMED`` when one disagrees, agrees with the prediction as well, or none comes within
  two windows; a fix to be used late whose key pose has left iSAM2's window is not added
  (``LEFT_WINDOW``: the batch smoother weighs it);
- a fix is *trusted* once a later fix from a window that shares none of its pings agrees with it
  through the DR; the last trusted fix is where a lost episode starts;
- windows whose precise fix lies beyond the search (``OUTSIDE_SEARCH``) or beyond the gate are
  evidence; ``lost_windows`` of them since the last trusted fix make the navigator *lost*: it
  gives up the untrusted fixes (``GIVEN_UP``) and widens its belief by a *break* (on the start's
  prior when no fix was ever trusted, else on the odometry into the current key), so the searches
  grow fourfold and the covariance it reports says how little it knows; the window is judged again
  on the widened belief and decided again;
- it relocalises on ``relocalise_fixes`` precise fixes from disjoint windows that agree with each
  other (a lost navigator's are ``CANDIDATE`` until then; the jump is taken by a break sized to it,
  placed before the first of them), or ends the episode at once when a precise fix agrees with the
  belief it gave up (a false alarm);
- fixes refused only by the gate while tracking are weighed the same way: when enough agree,
  the prediction was the wrong one.

The pings from the last trusted fix to the end of an episode are flagged lost.

Examples
--------
>>> from tangraph.graph import GraphConfig
>>> policy = FixPolicy.from_config(GraphConfig(), cell=5.0)
>>> state = PolicyState()
>>> state.lost, state.episodes
(False, ())
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import TYPE_CHECKING, NamedTuple, cast

import numpy as np

from tangraph.fix_records import FixStatus
from tangraph.geometry import gate_threshold, is_precise
from tangraph.graph.fixes import FixOutcome, LostEpisode

if TYPE_CHECKING:
    from tangraph.graph.config import GraphConfig
    from tangraph.matching import TerrainFix

__all__ = [
    "LEFT_WINDOW_DETAIL",
    "Action",
    "Agreement",
    "Candidate",
    "FixPolicy",
    "GiveUp",
    "Mark",
    "PolicyState",
    "Relocalise",
    "Use",
    "Widen",
    "Window",
]

#: The detail of a fix whose key pose left iSAM2's window before it could be used.
LEFT_WINDOW_DETAIL = "its key has left iSAM2's window"


class Candidate(NamedTuple):
    """A fix the policy remembers (held, a relocalisation candidate, or used and not yet
    trusted): its key, the first ping of its window, the fix (with the covariance the graph gives
    it), the predicted DR-frame pose of the key and the index of its record."""

    key: int
    first: int
    fix: TerrainFix
    pose: np.ndarray
    record: int


#: ``agree(earlier, later, at_key)``: whether ``later``'s fix agrees with ``earlier``'s through the
#: DR between their keys (NIS within the gate), the heading and calibration uncertainty taken from
#: the window's prediction, or from the latest key estimate when ``at_key``.
Agreement = Callable[[Candidate, Candidate, bool], bool]


@dataclasses.dataclass(frozen=True, eq=False)
class Window:
    """One TAP window as the policy sees it: its ``key``, the index of its ``record`` among the
    navigator's, its ``outcome``, the predicted DR-frame ``pose (3,)`` and world ``position (2,)``
    of its key, and what the navigator answers: ``agree`` (:data:`Agreement`), ``belief_nis`` (a
    lost navigator's: the NIS of the fix against the prediction without the episode's breaks, inf
    when it cannot be judged) and ``held_in_window`` (whether the held fix's key pose is still in
    iSAM2's window)."""

    key: int
    record: int
    outcome: FixOutcome
    pose: np.ndarray
    position: np.ndarray
    agree: Agreement
    belief_nis: float = math.inf
    held_in_window: bool = True

    @property
    def candidate(self) -> Candidate:
        fix = cast("TerrainFix", self.outcome.fix)  # a held window's outcome has a fix
        return Candidate(self.key, int(fix.first), fix, self.pose, self.record)


@dataclasses.dataclass(frozen=True, eq=False)
class PolicyState:
    """What the policy knows between windows: whether the navigator is ``lost``, its lost
    ``episodes``, the windows saying the prediction is wrong since the last trusted fix
    (``outside``), the ``last_trusted`` fix's ping, the ``held`` fix, the relocalisation
    ``consensus`` (agreeing candidates, in ping order), the fixes used and not yet trusted
    (``untrusted``), and ``rejudging``: a :class:`Widen` was just returned, so the next window is
    the same one judged again on the widened belief."""

    lost: bool = False
    episodes: tuple[LostEpisode, ...] = ()
    outside: int = 0
    last_trusted: int | None = None
    held: Candidate | None = None
    consensus: tuple[Candidate, ...] = ()
    untrusted: tuple[Candidate, ...] = ()
    rejudging: bool = False


@dataclasses.dataclass(frozen=True, eq=False)
class Use:
    """Add the candidate's fix to the graph and mark its record ``ACCEPTED`` (with ``detail``, or
    its record's own); one whose key pose has left iSAM2's window is not added (``LEFT_WINDOW``)."""

    candidate: Candidate
    detail: str = ""


@dataclasses.dataclass(frozen=True)
class Mark:
    """Give record ``record`` the ``status`` (``HELD``, ``UNCONFIRMED``, ``CANDIDATE`` or
    ``LEFT_WINDOW``) and ``detail``; nothing else changes."""

    record: int
    status: FixStatus
    detail: str


@dataclasses.dataclass(frozen=True)
class GiveUp:
    """Remove from the graph the fixes used after ping ``after`` and before ping ``before`` that
    are still in iSAM2: they were searched around the belief given up (``GIVEN_UP``)."""

    after: int
    before: int


@dataclasses.dataclass(frozen=True)
class Widen:
    """Widen the belief by a break of ``std`` (m): on the start's position prior when
    ``on_start`` and it is still in iSAM2, else on the odometry into the window's key; then judge
    the window again on the widened belief (strictly) and decide on that outcome."""

    std: float
    on_start: bool


@dataclasses.dataclass(frozen=True, eq=False)
class Relocalise:
    """Move the track onto ``candidates`` (in ping order, the window's own last) by a break of
    ``jump`` (m): on the start's position prior when ``on_start``, else on the odometry into the
    first candidate's key; where neither is still in iSAM2, on the odometry into the window's key,
    and only the last candidate is used. Those used are ``ACCEPTED`` ("relocalised"). ``since``:
    the episode's first ping."""

    candidates: tuple[Candidate, ...]
    jump: float
    on_start: bool
    since: int


#: What :meth:`FixPolicy.decide` asks the navigator to do, in order.
Action = Use | Mark | GiveUp | Widen | Relocalise


def _replace_last(episodes: tuple[LostEpisode, ...], **changes) -> tuple[LostEpisode, ...]:
    return (*episodes[:-1], dataclasses.replace(episodes[-1], **changes))


def _disjoint(candidates) -> int:
    """How many of ``candidates`` (in ping order) form a chain of windows that share no ping."""
    count, end = 0, -1
    for c in candidates:
        if c.first > end:
            count, end = count + 1, c.key
    return count


def _trusted(state: PolicyState, key: int) -> PolicyState:
    """``state`` once the fix of ``key`` is trusted: the evidence of being lost and the
    relocalisation candidates are cleared, and the fixes up to it need no more trust."""
    return dataclasses.replace(state, last_trusted=max(key, state.last_trusted or 0), outside=0,
                               consensus=(), untrusted=tuple(u for u in state.untrusted if u.key > key))


@dataclasses.dataclass(frozen=True)
class FixPolicy:
    """The rules of the online fix policy (see the module's docstring).

    Parameters
    ----------
    lost_windows, relocalise_fixes : int or None, int
        As ``GraphConfig``'s (None: never lost).
    confirm_nis : float
        NIS above which an accepted fix is held for confirmation (inf: never held).
    agreement_nis : float
        NIS limit of agreement between fixes, and with the belief given up.
    spacing : int
        Pings between window ends (a held fix waits two windows).
    half_width_sigmas : float
        Search half-width in stds of the prediction (a precise fix's std is a small share of it).
    widest : float
        Total break std (m) up to which a lost navigator widens: what the widest search can see.
    cell : float
        The map's cell (m): the smallest jump of a relocalisation.
    """

    lost_windows: int | None
    relocalise_fixes: int
    confirm_nis: float
    agreement_nis: float
    spacing: int
    half_width_sigmas: float
    widest: float
    cell: float

    @classmethod
    def from_config(cls, config: GraphConfig, cell: float) -> FixPolicy:
        """The policy of ``config`` on a map of ``cell`` metres (its smallest cell size)."""
        cell = float(cell)
        return cls(lost_windows=config.online.lost_windows, relocalise_fixes=config.online.relocalise_fixes,
                   confirm_nis=gate_threshold(config.online.confirm_probability),
                   agreement_nis=gate_threshold(config.fixes.gate_probability or 0.999),
                   spacing=config.spacing, half_width_sigmas=config.fixes.half_width_sigmas,
                   widest=config.fixes.max_half_width_cells * cell / config.fixes.half_width_sigmas,
                   cell=cell)

    def precise(self, outcome: FixOutcome, share: float = 0.5) -> bool:
        """Whether a fix's largest std is within ``share / half_width_sigmas`` of its search's
        half-width: an eighth by default, as a relocalisation candidate must be (two vague fixes
        agree with anything); a quarter for a window whose best match on the search's edge is
        evidence of being lost (a vague one there is a window of bad pings)."""
        covariance = cast("TerrainFix", outcome.fix).covariance
        return is_precise(covariance, outcome.record.half_width, self.half_width_sigmas, share)

    def decide(self, state: PolicyState, window: Window) -> tuple[PolicyState, tuple[Action, ...]]:
        """The next state and the actions for one window (neither input is changed).

        After a :class:`Widen` the state is ``rejudging``: the next call must be the same window
        judged again on the widened belief.
        """
        actions: list[Action] = []
        if state.rejudging:
            state = dataclasses.replace(state, rejudging=False)
            return self._weigh(state, window, True, actions), tuple(actions)
        if not state.lost:
            state, taken = self._confirm(state, window, actions)
            if taken:
                return state, tuple(actions)
        outcome = window.outcome
        evidence = outcome.record.status.says_lost and self.precise(outcome, 1.0)
        if evidence:
            state = dataclasses.replace(state, outside=state.outside + 1)  # the truth seems beyond the search
            if self.lost_windows is not None and state.outside >= self.lost_windows and window.key > 0:
                state, widening = self._widen(dataclasses.replace(state, outside=0), window, actions)
                if widening > 0:
                    actions.append(Widen(widening, on_start=state.episodes[-1].start == 0))
                    return dataclasses.replace(state, rejudging=True), tuple(actions)
        return self._weigh(state, window, evidence, actions), tuple(actions)

    def _confirm(self, state: PolicyState, window: Window, actions: list) -> tuple[PolicyState, bool]:
        """A tracking navigator's window: an accepted fix is used at once when it is close to the
        prediction, held when its NIS is above ``confirm_nis``; the held fix is used once a later
        accepted fix with an NIS above ``confirm_nis`` agrees with it through the DR, dropped when
        one disagrees, agrees with the prediction as well, or after two windows. Returns the
        state and whether the window's fix was accepted (used or held)."""
        held, agreed = state.held, False
        accepted = window.outcome.accepted
        if held is not None and (accepted or window.key - held.key > 2 * self.spacing):
            # a fix confirms the held one when it agrees with it and is itself as surprising to
            # the prediction the held one contradicts: a vague fix agrees with both, and tells
            # them apart no better than a fix that never came
            agrees = accepted and window.agree(held, window.candidate, False)
            agreed = agrees and window.outcome.record.nis > self.confirm_nis
            if agreed:
                state = self._use(state, held, f"confirmed by the fix at ping {window.key}", window, actions,
                                  in_window=window.held_in_window)
            else:
                why = ("no fix came to agree" if not accepted else "the next fix did not agree" if not agrees
                       else "the next fix agreed with the prediction as well")
                state = self._drop_held(state, why, actions)
            state = dataclasses.replace(state, held=None)
        if not accepted:
            return state, False
        if window.outcome.record.nis > self.confirm_nis and (held is None or not agreed):
            actions.append(Mark(window.record, FixStatus.HELD, "held until a later fix agrees"))
            return dataclasses.replace(state, held=window.candidate), True
        state = self._use(state, window.candidate, "", window, actions)
        return dataclasses.replace(state, consensus=()), True  # the gate's refusals before were bad windows

    def _use(self, state: PolicyState, candidate: Candidate, detail: str, window: Window, actions: list, *,
             trusted: bool = False, in_window: bool = True) -> PolicyState:
        """Use a fix. It is *trusted* (the last trusted fix is where a lost episode starts, and it
        clears the evidence of being lost) once a later used fix from a window that shares none of
        its pings agrees with it through the DR, or at once when ``trusted`` (a fix that agreed to
        relocalise); a multimodal fix never is (two places explain it). A fix whose key pose has
        left iSAM2's window (not ``in_window``) is not used."""
        if not in_window:
            actions.append(Mark(candidate.record, FixStatus.LEFT_WINDOW, LEFT_WINDOW_DETAIL))
            return state
        actions.append(Use(candidate, detail))
        if candidate.fix.quality.multimodal:
            return state
        if trusted:
            return _trusted(state, candidate.key)
        confirmed = [u.key for u in state.untrusted
                     if u.key < candidate.first and window.agree(u, candidate, True)]
        if confirmed:
            state = _trusted(state, max(confirmed))
        return dataclasses.replace(state, untrusted=(*state.untrusted, candidate))

    @staticmethod
    def _drop_held(state: PolicyState, why: str, actions: list) -> PolicyState:
        """Give up the held fix (if any): ``UNCONFIRMED``, saying ``why``."""
        if state.held is None:
            return state
        actions.append(Mark(state.held.record, FixStatus.UNCONFIRMED, f"held for confirmation; {why}"))
        return dataclasses.replace(state, held=None)

    @staticmethod
    def _give_up(state: PolicyState, after: int, before: int, actions: list) -> PolicyState:
        """Give up the fixes used after ping ``after`` (the last trusted fix) and before
        ``before``: none of them was trusted, and they were searched around the belief the
        navigator now gives up."""
        actions.append(GiveUp(after, before))
        kept = tuple(u for u in state.untrusted if not after < u.key < before)
        return dataclasses.replace(state, untrusted=kept)

    def _widen(self, state: PolicyState, window: Window, actions: list) -> tuple[PolicyState, float]:
        """Start (or go on with) a lost episode at the window's key and return by how much (std,
        m) to widen the belief: the search's half-width (the truth lies beyond it), up to what the
        widest search can still see (0 once there)."""
        k = window.key
        if not state.lost:
            state = self._drop_held(state, "the navigator was lost before a fix agreed", actions)
            start = 0 if state.last_trusted is None else state.last_trusted
            state = dataclasses.replace(state, lost=True,
                                        episodes=(*state.episodes, LostEpisode(start=start, declared=k)))
            state = self._give_up(state, start, k, actions)  # what was built on the belief now given up
        breaks = state.episodes[-1].breaks
        widened = float(np.sqrt(np.sum(np.square(breaks))))
        if widened >= self.widest:
            return state, 0.0
        std = min(float(window.outcome.record.half_width), float(np.sqrt(self.widest**2 - widened**2)))
        # candidates behind a break are tied to the old belief
        return dataclasses.replace(state, episodes=_replace_last(state.episodes, breaks=(*breaks, std)),
                                   consensus=()), std

    def _weigh(self, state: PolicyState, window: Window, evidence: bool, actions: list) -> PolicyState:
        """Relocalisation candidates: while lost, fixes that pass everything; while tracking,
        fixes that only the gate refused (the prediction may be the wrong one); either way precise
        ones. A lost navigator's candidate that agrees with the belief it gave up ends the episode;
        enough agreeing candidates from disjoint windows relocalise."""
        outcome = window.outcome
        gated = outcome.record.status is FixStatus.GATE
        usable = outcome.accepted if state.lost else (
            gated and not cast("TerrainFix", outcome.fix).quality.multimodal)
        if not usable or self.lost_windows is None or not self.precise(outcome):
            return state
        candidate = window.candidate
        if state.lost and not evidence and not window.belief_nis > self.agreement_nis:
            return self._resume(state, candidate, window, actions)
        if state.lost:
            actions.append(Mark(window.record, FixStatus.CANDIDATE, "relocalisation candidate"))
        consensus = state.consensus
        if consensus and not window.agree(consensus[-1], candidate, False):
            consensus = ()
        state = dataclasses.replace(state, consensus=(*consensus, candidate))
        if _disjoint(state.consensus) >= self.relocalise_fixes:
            state = self._relocalise(state, window, actions)
        return state

    def _resume(self, state: PolicyState, candidate: Candidate, window: Window, actions: list) -> PolicyState:
        """A lost navigator's candidate agrees with the belief it gave up: the evidence was bad
        windows, not a wrong belief. The candidate is used, trusted, and the episode ends there."""
        state = self._use(state, candidate, "the belief held", window, actions, trusted=True)
        return dataclasses.replace(state, lost=False, consensus=(),
                                   episodes=_replace_last(state.episodes, end=candidate.key))

    def _relocalise(self, state: PolicyState, window: Window, actions: list) -> PolicyState:
        """Enough agreeing candidates: the belief since the last trusted fix was wrong. Give up
        what was built on it, and move the track onto the candidates by a break as large as the
        newest one's distance from the prediction (at least a cell); the episode (a new one when
        tracking) ends at the window, and the held fix is dropped."""
        taken, k = state.consensus, window.key
        jump = max(float(np.hypot(*(taken[-1].fix.position - window.position))), self.cell)
        if state.lost:
            episodes = _replace_last(state.episodes, breaks=(*state.episodes[-1].breaks, jump))
        else:
            start = 0 if state.last_trusted is None else state.last_trusted
            episodes = (*state.episodes, LostEpisode(start=start, declared=taken[0].key, breaks=(jump,)))
        start = episodes[-1].start
        state = self._give_up(dataclasses.replace(state, episodes=episodes), start, k, actions)
        actions.append(Relocalise(taken, jump, on_start=start == 0, since=start))
        state = _trusted(state, taken[-1].key)  # the window's own fix, trusted as it is used
        state = dataclasses.replace(state, episodes=_replace_last(state.episodes, end=k))
        state = self._drop_held(state, "the navigator relocalised before a fix agreed", actions)
        return dataclasses.replace(state, lost=False)
