"""The online fix policy as pure functions: windows in, a new state and actions out, no graph.

A window's fix is given as where it puts the vehicle relative to the prediction (``position``);
two fixes *agree* here when they put it within 5 m of each other (the navigator judges that
through the dead reckoning), and the prediction is at the origin.
"""

from __future__ import annotations

import ast
import inspect
import math
from types import SimpleNamespace

import numpy as np
import pytest

from tangraph.graph import FixRecord, FixStatus, GraphConfig, LostEpisode
from tangraph.graph import policy as policy_module
from tangraph.graph.fixes import FixOutcome
from tangraph.graph.policy import (
    LEFT_WINDOW_DETAIL,
    FixPolicy,
    GiveUp,
    Mark,
    PolicyState,
    Relocalise,
    Use,
    Widen,
    Window,
)

CONFIG = GraphConfig()  # lost after 4 windows, relocalised on 2 fixes, held above the 0.9 quantile
POLICY = FixPolicy.from_config(CONFIG, cell=5.0)
HALF_WIDTH = 40.0  # m: the searches' (a precise fix's std is at most 5 m)
SURPRISING = 8.0  # NIS between the confirmation quantile (4.6) and the gate (13.8)
DROPPED = "held for confirmation; "  # a dropped held fix's detail begins so


def close(a, b, at_key) -> bool:
    return bool(np.hypot(*(a.fix.position - b.fix.position)) < 5.0)


def never(a, b, at_key) -> bool:
    return False


def window(key: int, status: FixStatus = FixStatus.ACCEPTED, *, record: int = 0, nis: float = 1.0,
           position=(0.0, 0.0), std: float = 1.0, first: int | None = None, multimodal: bool = False,
           agree=close, belief_nis: float = math.inf, held_in_window: bool = True,
           fix: bool = True) -> Window:
    """The window ending at ping ``key`` (by default of the 10 pings up to it)."""
    first = key - 9 if first is None else first
    made = SimpleNamespace(first=first, position=np.asarray(position, float), covariance=np.eye(2) * std**2,
                           quality=SimpleNamespace(multimodal=multimodal)) if fix else None
    north, east = (position if fix else (math.nan, math.nan))
    rec = FixRecord(key, north, east, std**2, 0.0, std**2, status, nis if fix else math.nan, HALF_WIDTH)
    return Window(key, record, FixOutcome(rec, made), np.array([float(key), 0.0, 0.0]), np.zeros(2), agree,
                  belief_nis, held_in_window)


def run(windows, state: PolicyState | None = None, policy: FixPolicy = POLICY):
    """Decide on ``windows`` in turn (each judged again as it is after a widening); the last
    state and every action."""
    state = state or PolicyState()
    actions = []
    for w in windows:
        state, done = policy.decide(state, w)
        actions.extend(done)
        if state.rejudging:
            state, done = policy.decide(state, w)
            actions.extend(done)
    return state, actions


def summary(actions) -> list[tuple]:
    """Actions as plain tuples (the candidates by their records)."""
    out = []
    for a in actions:
        if isinstance(a, Use):
            out.append(("use", a.candidate.record, a.detail))
        elif isinstance(a, Mark):
            out.append(("mark", a.record, a.status, a.detail))
        elif isinstance(a, GiveUp):
            out.append(("give up", a.after, a.before))
        elif isinstance(a, Widen):
            out.append(("widen", a.std, a.on_start))
        elif isinstance(a, Relocalise):
            out.append(("relocalise", tuple(c.record for c in a.candidates), a.jump, a.on_start, a.since))
    return out


def lost_at(key: int, *, trusted: int | None = None) -> PolicyState:
    """A navigator declared lost at ``key`` (no fix trusted unless ``trusted``), widened once."""
    start = 0 if trusted is None else trusted
    episode = LostEpisode(start, key, breaks=(HALF_WIDTH,))
    return PolicyState(lost=True, episodes=(episode,), last_trusted=trusted)


def test_the_policy_imports_nothing_of_gtsam():
    tree = ast.parse(inspect.getsource(policy_module))
    imported = {node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)}
    imported |= {alias.name for node in ast.walk(tree) if isinstance(node, ast.Import)
                 for alias in node.names}
    assert not {m for m in imported if "gtsam" in m or m.split(".")[-1] in ("online", "lost", "keyposes",
                                                                          "calibration", "smoother")}


def test_a_close_fix_is_used_at_once():
    state, actions = POLICY.decide(PolicyState(), window(9))
    assert summary(actions) == [("use", 0, "")]
    assert state.held is None and [u.record for u in state.untrusted] == [0] and state.last_trusted is None


def test_a_surprising_fix_is_held_then_used_when_a_later_disjoint_fix_agrees():
    held, actions = POLICY.decide(PolicyState(), window(19, nis=SURPRISING, position=(3.0, 0.0)))
    assert summary(actions) == [("mark", 0, FixStatus.HELD, "held until a later fix agrees")]
    assert held.held.record == 0 and held.untrusted == ()
    state, actions = POLICY.decide(held, window(29, record=1, nis=SURPRISING, position=(3.0, 1.0)))
    assert summary(actions) == [("use", 0, "confirmed by the fix at ping 29"), ("use", 1, "")]
    # the held fix is trusted: the later one agrees with it from a window sharing none of its pings
    assert state.held is None and state.last_trusted == 19 and [u.record for u in state.untrusted] == [1]


def test_a_held_fix_is_unconfirmed_by_a_later_one_that_agrees_with_the_prediction_too():
    """A later fix close to both the held fix and the prediction cannot tell them apart: the
    held fix is dropped, the later one used."""
    held, _ = POLICY.decide(PolicyState(), window(19, nis=SURPRISING, position=(3.0, 0.0)))
    state, actions = POLICY.decide(held, window(29, record=1, position=(1.0, 0.0)))
    assert summary(actions) == [
        ("mark", 0, FixStatus.UNCONFIRMED, f"{DROPPED}the next fix agreed with the prediction as well"),
        ("use", 1, "")]
    assert state.held is None and [u.record for u in state.untrusted] == [1]


def test_a_held_fix_a_later_one_contradicts_is_unconfirmed():
    held, _ = POLICY.decide(PolicyState(), window(19, nis=SURPRISING, position=(9.0, 0.0)))
    state, actions = POLICY.decide(held, window(29, record=1))
    assert summary(actions) == [("mark", 0, FixStatus.UNCONFIRMED, f"{DROPPED}the next fix did not agree"),
                                ("use", 1, "")]
    assert state.held is None and [u.record for u in state.untrusted] == [1]


def test_a_held_fix_whose_key_left_the_window_is_left():
    held, _ = POLICY.decide(PolicyState(), window(19, nis=SURPRISING))
    state, actions = POLICY.decide(held, window(29, record=1, nis=SURPRISING, held_in_window=False))
    assert summary(actions) == [("mark", 0, FixStatus.LEFT_WINDOW, LEFT_WINDOW_DETAIL), ("use", 1, "")]
    assert [u.record for u in state.untrusted] == [1] and state.last_trusted is None


def test_a_held_fix_no_fix_comes_to_agree_with_is_unconfirmed_after_two_windows():
    held, _ = POLICY.decide(PolicyState(), window(19, nis=SURPRISING))
    state, actions = run([window(29, FixStatus.MISFIT, record=1), window(39, FixStatus.MATCH_FAILED, record=2,
                                                                         fix=False)], held)
    assert actions == [] and state.held.record == 0  # two windows: it still waits
    state, actions = POLICY.decide(state, window(49, FixStatus.MATCH_FAILED, record=3, fix=False))
    assert summary(actions) == [("mark", 0, FixStatus.UNCONFIRMED, f"{DROPPED}no fix came to agree")]
    assert state.held is None


def test_without_confirmation_a_surprising_fix_is_used():
    policy = FixPolicy.from_config(CONFIG.replace(confirm_probability=None), cell=5.0)
    state, actions = policy.decide(PolicyState(), window(19, nis=SURPRISING))
    assert summary(actions) == [("use", 0, "")] and state.held is None


def test_lost_windows_of_evidence_make_it_lost_and_give_up_the_untrusted_fixes():
    def outside(key, record):
        return window(key, FixStatus.OUTSIDE_SEARCH, record=record, position=(60.0, 0.0))

    state, actions = run([window(9, record=0), outside(19, 1), outside(29, 2), outside(39, 3),
                          window(49, record=4, nis=SURPRISING)])
    assert summary(actions) == [("use", 0, ""), ("mark", 4, FixStatus.HELD, "held until a later fix agrees")]
    assert not state.lost and state.outside == 3 and [u.record for u in state.untrusted] == [0]
    state, actions = POLICY.decide(state, outside(59, 5))
    assert summary(actions) == [
        ("mark", 4, FixStatus.UNCONFIRMED, f"{DROPPED}the navigator was lost before a fix agreed"),
        ("give up", 0, 59), ("widen", HALF_WIDTH, True)]  # no fix trusted: the start's prior widened
    assert state.lost and state.rejudging and state.untrusted == () and state.held is None
    assert state.episodes == (LostEpisode(start=0, declared=59, breaks=(HALF_WIDTH,)),)
    state, actions = POLICY.decide(state, outside(59, 5))  # judged again: still beyond the search
    assert actions == () and state.lost and not state.rejudging and state.outside == 0


def test_the_window_judged_again_in_the_widened_search_is_a_candidate():
    """Found within the widened search, the window's fix is a relocalisation candidate: being
    evidence of the wrong belief, it cannot say the belief held."""
    outside = [window(k, FixStatus.OUTSIDE_SEARCH, record=n, position=(60.0, 0.0))
               for n, k in enumerate((9, 19, 29, 39))]
    state, _ = run(outside[:3])
    state, actions = POLICY.decide(state, outside[3])
    assert state.rejudging and isinstance(actions[-1], Widen)
    state, actions = POLICY.decide(state, window(39, record=3, position=(60.0, 0.0), belief_nis=0.0))
    assert summary(actions) == [("mark", 3, FixStatus.CANDIDATE, "relocalisation candidate")]
    assert state.lost and [c.record for c in state.consensus] == [3]


def test_a_lost_episode_starts_at_the_last_trusted_fix():
    trusted, _ = run([window(9, record=0), window(19, record=1)])
    assert trusted.last_trusted == 9
    state, actions = run([window(k, FixStatus.GATE, record=n, nis=50.0, position=(60.0, 0.0), multimodal=True)
                          for n, k in enumerate(range(29, 69, 10), start=2)], trusted)
    assert summary(actions) == [("give up", 9, 59), ("widen", HALF_WIDTH, False)]
    assert state.episodes[0].start == 9 and state.untrusted == ()


def test_vague_windows_beyond_the_search_are_no_evidence():
    state, actions = run([window(k, FixStatus.OUTSIDE_SEARCH, record=n, std=20.0)
                          for n, k in enumerate(range(9, 99, 10))])
    assert actions == [] and not state.lost and state.outside == 0


def test_without_lost_windows_the_navigator_is_never_lost():
    policy = FixPolicy.from_config(CONFIG.replace(lost_windows=None), cell=5.0)
    windows = [window(k, FixStatus.OUTSIDE_SEARCH, record=n) for n, k in enumerate(range(9, 99, 10))]
    state, actions = run(windows, policy=policy)
    assert actions == [] and not state.lost and state.episodes == ()


def test_a_lost_navigator_widens_only_up_to_the_widest_search():
    """Every widening is the search's half-width; the breaks together reach what the widest
    search can see (200 cells over 4 stds: 250 m), then no more."""
    windows = [window(k, FixStatus.OUTSIDE_SEARCH, record=n) for n, k in enumerate(range(9, 2009, 10))]
    state, actions = run(windows)
    widenings = [a.std for a in actions if isinstance(a, Widen)]
    breaks = state.episodes[-1].breaks
    assert POLICY.widest == pytest.approx(250.0) and len(state.episodes) == 1
    assert widenings == list(breaks) and widenings[:39] == [HALF_WIDTH] * 39
    assert len(widenings) < len(windows) // CONFIG.online.lost_windows  # it stopped widening
    assert np.sqrt(np.sum(np.square(breaks))) == pytest.approx(POLICY.widest)


def test_it_relocalises_on_agreeing_candidates_from_disjoint_windows():
    candidates = [window(k, record=n, position=(60.0, -1.0 * n)) for n, k in enumerate((69, 79))]
    state, actions = run(candidates, lost_at(59))
    jump = float(np.hypot(60.0, -1.0))
    assert summary(actions) == [("mark", 0, FixStatus.CANDIDATE, "relocalisation candidate"),
                                ("mark", 1, FixStatus.CANDIDATE, "relocalisation candidate"),
                                ("give up", 0, 79), ("relocalise", (0, 1), jump, True, 0)]
    assert not state.lost and state.last_trusted == 79 and state.consensus == ()
    assert state.episodes == (LostEpisode(start=0, declared=59, end=79, breaks=(HALF_WIDTH, jump)),)


@pytest.mark.parametrize("second", [dict(first=65), dict(position=(90.0, 0.0)), dict(std=6.0)],
                         ids=["shares pings", "disagrees", "vague"])
def test_no_relocalisation_on_overlapping_disagreeing_or_vague_candidates(second):
    first = window(69, record=0, position=(60.0, 0.0))
    state, actions = run([first, window(79, record=1, **{"position": (60.0, 0.5), **second})], lost_at(59))
    assert state.lost and not any(isinstance(a, Relocalise) for a in actions)
    assert state.episodes[-1].end is None


def test_a_false_alarm_ends_when_a_fix_agrees_with_the_belief_given_up():
    state, actions = POLICY.decide(lost_at(59, trusted=39), window(69, belief_nis=2.0))
    assert summary(actions) == [("use", 0, "the belief held")]
    assert not state.lost and state.last_trusted == 69
    assert state.episodes == (LostEpisode(start=39, declared=59, end=69, breaks=(HALF_WIDTH,)),)


def test_gate_refusals_that_agree_while_tracking_make_the_prediction_the_wrong_one():
    tracking, _ = run([window(9, record=0), window(19, record=1)])  # 9 trusted, 19 not yet
    refused = [window(k, FixStatus.GATE, record=n, nis=50.0, position=(30.0, 0.0))
               for n, k in enumerate((29, 39), start=2)]
    state, actions = run(refused[:1], tracking)
    assert actions == [] and [c.record for c in state.consensus] == [2]
    state, actions = POLICY.decide(state, refused[1])
    assert summary(actions) == [("give up", 9, 39), ("relocalise", (2, 3), 30.0, False, 9)]
    assert not state.lost and state.last_trusted == 39 and state.untrusted == ()
    assert state.episodes == (LostEpisode(start=9, declared=29, end=39, breaks=(30.0,)),)


def test_a_used_fix_between_gate_refusals_says_the_prediction_held():
    refused = dict(nis=50.0, position=(30.0, 0.0))
    state, actions = run([window(29, FixStatus.GATE, record=0, **refused), window(39, record=1),
                          window(49, FixStatus.GATE, record=2, **refused)])
    assert summary(actions) == [("use", 1, "")] and [c.record for c in state.consensus] == [2]


def test_a_multimodal_gate_refusal_is_no_candidate():
    state, actions = run([window(k, FixStatus.GATE, record=n, nis=50.0, position=(30.0, 0.0), multimodal=True)
                          for n, k in enumerate((29, 39))])
    assert actions == [] and state.consensus == ()
