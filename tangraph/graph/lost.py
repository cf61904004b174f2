"""Lost and relocalisation, the navigator's side: the fix policy's windows and actions on the graph.

What the online navigator does with each fix beyond the gate, how it finds out that it is lost
and how it relocalises is decided by the pure fix policy (:mod:`tangraph.graph.policy`: held and
confirmed fixes, trust, the lost episodes, breaks, relocalisation). This module is the
:class:`~tangraph.graph.GraphNavigator`'s side of it: :func:`take_window` judges a window, puts it
to the policy with what only the navigator knows (:func:`window`: agreement through the dead
reckoning (:func:`agreement`), the NIS against the belief given up, whether a key pose is still in
iSAM2's window) and executes the actions (:func:`execute`) on the navigator's pose graph and
iSAM2 smoother: fix factors added, given-up fixes removed, breaks on the start's position prior
or on odometry factors (iSAM2 factors are replaced: removed by index, re-added widened), and
the fix records' statuses.
"""

from __future__ import annotations

import dataclasses
import logging
import math
from typing import TYPE_CHECKING

import numpy as np

from tangraph.fix_records import FixStatus
from tangraph.graph.calibration import to_world, world_jacobian
from tangraph.graph.factors import compose, nis
from tangraph.graph.fixes import FixOutcome
from tangraph.graph.keyposes import increments
from tangraph.graph.policy import (
    LEFT_WINDOW_DETAIL,
    Action,
    Candidate,
    GiveUp,
    Mark,
    PolicyState,
    Relocalise,
    Use,
    Widen,
    Window,
)
from tangraph.sensors import rotation_matrix

if TYPE_CHECKING:
    from tangraph.graph.online import GraphNavigator
    from tangraph.matching import TerrainFix

__all__ = ["agreement", "execute", "take_window", "use", "window"]

log = logging.getLogger("tangraph.graph.online")  # the navigator's messages, one logger for them


def _widened(joint, variance: float) -> np.ndarray:
    """A joint covariance with ``variance`` (m^2) added to its position's (a break's)."""
    joint = np.array(joint, float)
    joint[0, 0] += variance
    joint[1, 1] += variance
    return joint


def take_window(nav: GraphNavigator, k: int, pose, joint, fix: TerrainFix | None) -> float:
    """Make (or take) the fix of ping ``k`` (DR-frame ``pose`` and its ``joint`` covariance),
    judge it, let the navigator's fix policy decide and execute its actions; after a widening the
    window is judged again on the widened belief and decided again. Returns the std (m) of the
    break to put on the odometry into key ``k`` (0 for none)."""
    if fix is None and not nav._is_end[k]:
        return 0.0
    outcome = nav._judge(k, pose, joint, fix, strict=nav.state.lost)
    nav.fixes.append(outcome.record)
    extra, actions = _decide(nav, window(nav, nav.state, k, pose, joint, outcome))
    if nav.state.rejudging:
        widen = next(a for a in actions if isinstance(a, Widen))
        joint = _widened(joint, widen.std**2)
        outcome = nav._judge(k, pose, joint, fix, strict=True)
        nav.fixes[-1] = outcome.record
        more, _ = _decide(nav, window(nav, nav.state, k, pose, joint, outcome))
        extra = float(np.hypot(extra, more))
    return extra


def _decide(nav: GraphNavigator, seen: Window) -> tuple[float, tuple[Action, ...]]:
    """One decision of the navigator's policy, executed: the navigator keeps the new state.
    Returns the std of the break into the window's key and the actions."""
    state = nav.state
    nav.state, actions = nav.policy.decide(state, seen)
    extra = execute(nav, actions, seen.key)
    if nav.state.lost and not state.lost:
        log.warning("graph: lost at ping %d (the best matches lie beyond the search since ping %d)",
                    seen.key, nav.state.episodes[-1].start)
    elif state.lost and not nav.state.lost and not any(isinstance(a, Relocalise) for a in actions):
        log.warning("graph: back on track at ping %d: the fix agrees with the belief held before ping %d",
                    seen.key, nav.state.episodes[-1].declared)
    return extra, actions


def window(nav: GraphNavigator, state: PolicyState, k: int, pose, joint, outcome: FixOutcome) -> Window:
    """The window of ping ``k`` as the policy in ``state`` sees it, with the navigator's answers:
    agreement through the DR (:func:`agreement`, with ``joint`` or the latest key's), the NIS of a
    lost navigator's fix against the prediction without the episode's breaks, and whether the held
    fix's key pose is still in iSAM2's window."""
    pose = np.asarray(pose, float).copy()
    position = to_world(pose, nav.calibration, nav.origin)[:2]

    def agree(a: Candidate, b: Candidate, at_key: bool) -> bool:
        return agreement(nav, a, b, nav._key_joint if at_key else joint)

    belief = math.inf
    if state.lost and not state.rejudging and outcome.fix is not None:
        widened = float(np.sum(np.square(state.episodes[-1].breaks)))
        world, cov = nav._world(pose, _widened(joint, -widened))
        total = cov[:2, :2] + outcome.fix.covariance
        if np.linalg.eigvalsh(total).min() > 0:
            belief = nis(outcome.fix.position - world[:2], total)
    held = state.held is None or _in_window(nav, state.held.key)
    return Window(k, len(nav.fixes) - 1, outcome, pose, position, agree, belief, held)


def execute(nav: GraphNavigator, actions: tuple[Action, ...], k: int) -> float:
    """Do the policy's ``actions`` for the window of ping ``k`` on the navigator's graph, iSAM2
    and fix records, in order. Returns the std (m) of the break to put on the odometry into key
    ``k`` (0 for none)."""
    extra = 0.0
    for action in actions:
        if isinstance(action, Use):
            use(nav, action.candidate, action.detail)
        elif isinstance(action, Mark):
            nav.fixes[action.record] = dataclasses.replace(nav.fixes[action.record], status=action.status,
                                                           detail=action.detail)
        elif isinstance(action, GiveUp):
            _give_up(nav, action.after, action.before)
        elif isinstance(action, Widen):
            # on the start's prior (the belief given up when no fix was ever trusted: widening it
            # keeps the constant DR errors from bending to reconcile it with the fixes)
            on_start = action.on_start and _widen_start(nav, action.std)
            extra = float(np.hypot(extra, 0.0 if on_start else action.std))
        elif isinstance(action, Relocalise):
            extra = float(np.hypot(extra, _relocalise(nav, action, k)))
    return extra


def _in_window(nav: GraphNavigator, key: int) -> bool:
    return nav.isam.getLinearizationPoint().exists(key) or nav._new_values.exists(key)


def use(nav: GraphNavigator, candidate: Candidate, detail: str) -> None:
    """Add a fix to the graph and mark its record ``ACCEPTED`` (with ``detail``, or the record's
    own). A fix whose key pose has left iSAM2's window (``isam_window``) is not added: it is
    ``LEFT_WINDOW``, for the batch smoother."""
    fix, key = candidate.fix, candidate.key
    record = nav.fixes[candidate.record]
    if not _in_window(nav, key):
        nav.fixes[candidate.record] = dataclasses.replace(record, status=FixStatus.LEFT_WINDOW,
                                                          detail=LEFT_WINDOW_DETAIL)
        return
    factor = nav.graph.add_position_fix(key, fix.position, fix.covariance, nav._fix_factor(key, fix))
    nav._new_factors.add(factor)
    nav.fixes[candidate.record] = dataclasses.replace(record, status=FixStatus.ACCEPTED,
                                                      detail=detail or record.detail)


def _relocalise(nav: GraphNavigator, action: Relocalise, k: int) -> float:
    """Take the relocalisation's jump by a break on the start's prior or on the odometry into the
    first candidate's key (so the jump is the break's and not the constant DR errors'), and add
    the candidates; where that has left iSAM2's window, only the newest is added (the others
    stay as they were, for the batch smoother) and the break goes into key ``k``, whose std is
    returned (0 otherwise)."""
    taken, extra, jump = action.candidates, 0.0, action.jump
    if not ((action.on_start and _widen_start(nav, jump)) or _break_into(nav, taken[0].key, jump)):
        taken, extra = taken[-1:], jump
    for candidate in taken:
        use(nav, candidate, "relocalised")
    log.warning("graph: relocalised at ping %d (lost since ping %d)", k, action.since)
    return extra


def _isam_index(nav: GraphNavigator, factor) -> int | None:
    """The index of ``factor`` in iSAM2's graph (None if it is not there any more)."""
    factors = nav.smoother.getFactors()
    return next((i for i in range(factors.size()) if factors.at(i) is factor), None)


def _give_up(nav: GraphNavigator, after: int, before: int) -> None:
    """Remove from iSAM2 the fixes used after ping ``after`` and before ``before`` (those still
    in it); their records become ``GIVEN_UP`` (the batch smoother weighs them again)."""
    graph = nav.graph
    keep = []
    for n, (key, _, _) in enumerate(graph.fixes):
        index = _isam_index(nav, graph._factors["fix"][n]) if after < key < before else None
        if index is None:
            keep.append(n)
            continue
        nav._remove.append(index)
        at = next(i for i, r in enumerate(nav.fixes) if r.index == key and r.accepted)
        nav.fixes[at] = dataclasses.replace(
            nav.fixes[at], status=FixStatus.GIVEN_UP,
            detail=f"given up at ping {before}: the navigator found its belief wrong")
    graph.fixes = [graph.fixes[n] for n in keep]
    graph._factors["fix"] = [graph._factors["fix"][n] for n in keep]


def _widen_start(nav: GraphNavigator, std: float) -> bool:
    """Replace the start's position prior in iSAM2 by one wider by ``std``
    (:meth:`~tangraph.graph.PoseGraph.widen_start`); False when the first pose has been
    marginalised."""
    index = _isam_index(nav, nav._start_factor)
    if index is None or not nav.isam.getLinearizationPoint().exists(0):
        return False
    nav._remove.append(index)
    factor = nav.graph.widen_start(std)
    nav._start_factor = factor
    nav._new_factors.add(factor)
    return True


def _break_into(nav: GraphNavigator, key: int, std: float) -> bool:
    """Widen by ``std`` the odometry factor into ``key`` in iSAM2 (a break after the fact);
    False when it has left iSAM2's window."""
    graph = nav.graph
    n = next((n for n, odo in enumerate(graph.odometry) if odo[1] == key), None)
    index = None if n is None else _isam_index(nav, graph._factors["odometry"][n])
    if index is None or key == 0:
        return False
    assert n is not None  # index is None without n
    total = float(np.hypot(graph.breaks.get(key, 0.0), std))
    graph.breaks[key] = total
    graph._factors["odometry"][n] = graph._odometry_factor(*graph.odometry[n], total)
    nav._remove.append(index)
    nav._new_factors.add(graph._factors["odometry"][n])
    return True


def agreement(nav: GraphNavigator, a: Candidate, b: Candidate, joint) -> bool:
    """Whether candidate ``b`` agrees with the earlier ``a`` through the DR between them: the
    NIS of the difference of their fixes against the DR's world displacement from ``a``'s
    predicted pose (white DR noise of the increment, ``a``'s heading and the calibration's
    covariance from ``joint``) is within the policy's ``agreement_nis``. ``b``'s own prediction is
    not used: it holds the corrections of the fixes used since ``a``, ``a``'s own among them."""
    survey = nav.survey
    delta, q = increments(nav.white, survey.time, survey.dr_pose, [a.key], [b.key])
    positions = np.array([a.pose, compose(a.pose, delta[0])])
    world = to_world(positions, nav.calibration, nav.origin)
    jac = world_jacobian(positions, nav.calibration, nav.origin)
    rot = jac[1, :2, :2] @ rotation_matrix(a.pose[2])  # a's frame to the world
    turn = jac[1, :2, :2] @ rotation_matrix(a.pose[2] + np.pi / 2) @ delta[0, :2]  # d / d heading
    shape = jac[1, :2, 3:] - jac[0, :2, 3:]
    cov = (a.fix.covariance + b.fix.covariance + rot @ q[0, :2, :2] @ rot.T
           + shape @ joint[3:, 3:] @ shape.T + np.outer(turn, turn) * joint[2, 2])
    error = b.fix.position - a.fix.position - (world[1, :2] - world[0, :2])
    return nis(error, cov) <= nav.policy.agreement_nis
