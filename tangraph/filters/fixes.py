"""Batch terrain fixes (TERCOM / grid-search MLE) as the TERCOM-PF and MLE filters use them.

A fix matches the window of the last ``window`` pings against the map by
:func:`tangraph.matching.tap_fix` (the TAP grid search, criterion MSD or MLE) over a square of
half-width ``search_sigmas`` times the predicted position std (the largest axis of the
predicted covariance), clipped to ``[min_half_width, max_half_width]`` (``min_half_width`` None:
the larger of 3 map cells and the model's ``initial_position_std``), around the predicted position;
the window is laid with the dead reckoning the filter's calibration estimate corrects, and the fix
grown by what is still uncertain of it (``attempt_fix``'s ``calibration``). Each
attempt is recorded as a :class:`tangraph.fix_records.FixRecord`, as the graph's are: what
became of it (used, held, confirmed, unconfirmed, too vague, or why TAP refused it), its NIS
against the prediction and the search's half-width.

What a filter does with an accepted fix is decided by :func:`decide_fix`, the rule the online
graph's fix policy (:mod:`tangraph.graph.policy`) applies to its windows, without the graph: a fix
whose NIS against the prediction is within the ``confirm_probability`` quantile of ``chi2(2)`` is
used at once; a surprising one is *held* (:class:`HeldFix`) until a later accepted fix, as
surprising to the prediction and precise for its search (its largest std within half of the
search's half-width over ``search_sigmas``, as the graph's relocalisation demands:
:func:`tangraph.geometry.is_precise`), agrees with it through the dead reckoning between them
(NIS within the ``gate`` under both fixes' covariances and the DR displacement's): both then say
the prediction is wrong, and the later fix is used. A vague fix that agrees with the held one
and is as surprising is not used and the held fix waits (a vague fix agrees with anything near
it: a drifted prediction's wrong match was confirmed so). A held fix is dropped when a later
accepted fix agrees with the prediction and not with it, or none confirms it within
``HOLD_ATTEMPTS`` fix attempts; a later fix that agrees with both (a vague one) is used and tells
nothing about it. One wrong match on a map whose error lets a false basin win (a poorly mapped
gap) is then never taken, while two agreeing matches still relocalise a filter whose prediction
is wrong.
"""

from __future__ import annotations

import dataclasses
import logging
import weakref
from typing import NamedTuple

import numpy as np

from tangraph.errors import TangraphError
from tangraph.fix_records import FixRecord, FixStatus
from tangraph.geometry import gate_threshold, is_precise, mahalanobis2
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import (
    Criterion,
    MatchingError,
    TapConfig,
    TapFix,
    calibrated_window,
    shape_covariance,
    tap_fix,
    tap_fix_patch,
    window_patch,
)
from tangraph.sensors import survey_map_error
from tangraph.survey import Survey
from tangraph.validation import check_count, check_number

__all__ = [
    "HOLD_ATTEMPTS",
    "FixDecision",
    "HeldFix",
    "attempt_fix",
    "check_fix_search",
    "decide_fix",
    "decided",
    "expired",
    "fix_due",
    "fix_window",
    "waited",
]

_log = logging.getLogger(__name__)


#: Fix attempts after a held fix within which a later fix must confirm it.
HOLD_ATTEMPTS = 2


def check_fix_search(config) -> None:
    """Validate (in ``__post_init__``) the fix-search fields of a config: ``window`` (pings per
    fix; None: :func:`fix_window`), ``fix_interval`` (pings between fixes; None: ``window``),
    ``criterion`` (mle or msd), ``search_sigmas``, ``min_half_width`` (None: 3 cells or the start std),
    ``max_half_width``, ``confirm_probability`` (None or in (0, 1); :func:`decide_fix`) and
    ``gate`` (> 0)."""
    if config.window is not None:
        check_count(config, "window")
    if config.fix_interval is not None:
        check_count(config, "fix_interval")
    check_number(config, "search_sigmas", open_low=True)
    check_number(config, "max_half_width", open_low=True)
    if config.min_half_width is not None:
        check_number(config, "min_half_width", open_low=True)
    check_number(config, "gate", open_low=True)
    if config.confirm_probability is not None and check_number(
        config, "confirm_probability", open_low=True, high=1.0
    ) == 1.0:
        raise TangraphError(
            f"{type(config).__name__}.confirm_probability must be None or lie in (0, 1), got 1.0"
        )
    if not hasattr(config, "criterion"):
        return
    try:
        criterion = Criterion(config.criterion)
    except ValueError:
        criterion = None
    if criterion not in (Criterion.MLE, Criterion.MSD):
        raise TangraphError(
            f"{type(config).__name__}.criterion must be mle or msd, got {config.criterion!r}"
        )
    object.__setattr__(config, "criterion", criterion)


def fix_window(config, survey: Survey) -> int:
    """Pings per fix: ``config.window``, or if None enough pings for about 30 soundings and at
    least 5 (Han et al.'s 5 pings of multibeam; 30 pings of a single beam); the latter is computed
    once per survey (cached while the survey lives), so a step may call this at every ping."""
    if config.window is not None:
        return int(config.window)
    cached = _DEFAULT_WINDOWS.get(survey)
    if cached is None:  # one scan of the soundings per survey, not one per step
        has = np.isfinite(survey.beam_depth)
        per_ping = has.sum() / max(int(has.any(axis=1).sum()), 1)
        cached = _DEFAULT_WINDOWS[survey] = int(max(5, np.ceil(30.0 / per_ping)))
    return cached


# The default window of each live survey (surveys are immutable and hashed by identity).
_DEFAULT_WINDOWS: weakref.WeakKeyDictionary[Survey, int] = weakref.WeakKeyDictionary()


def fix_due(config, index: int, window: int) -> bool:
    """Whether a fix is searched at ping ``index``: the first full window, then every
    ``fix_interval`` pings (default: ``window``, so windows do not overlap)."""
    first = window - 1
    return index >= first and (index - first) % int(config.fix_interval or window) == 0


def attempt_fix(
    survey: Survey,
    bathymetry: BathymetryMap,
    index: int,
    prior: np.ndarray,
    covariance: np.ndarray,
    search,
    window: int,
    *,
    initial_std: float = 0.0,
    model=None,
    calibration: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[TapFix | None, FixRecord]:
    """The fix of the window ending at ping ``index`` searched around ``prior``, and its record
    (``ACCEPTED`` until the filter judges it, else why TAP refused it; ``None`` and
    ``MATCH_FAILED`` when no match can be made). ``initial_std`` (the
    model's start std) is the smallest half-width when ``search.min_half_width`` is None (with
    3 map cells). ``model``: the run's navigation model, whose map error widens the fix by what
    its soundings share with the survey's others (:func:`tangraph.sensors.shared_map_variances`,
    computed once per survey, map and model). ``calibration``: the filter's estimate of the DR's
    constant errors ``(k, b)`` and their covariance ``(2, 2)``; the window is then laid with the
    dead reckoning they correct (:func:`tangraph.matching.calibrated_window`), not the raw one,
    and the fix's covariance grows by what is still uncertain of that laying (the model's white
    DR noise and the calibration's covariance, :func:`tangraph.matching.shape_covariance`), as
    the graph lays and grows its windows; it needs ``model``."""
    cell = min(bathymetry.cell_size)
    spread = np.sqrt(np.max(np.linalg.eigvalsh(covariance))) if np.all(np.isfinite(covariance)) else np.inf
    low = search.min_half_width
    if low is None:
        low = max(3.0 * cell, float(initial_std))
    half_width = float(np.clip(search.search_sigmas * spread, low, max(low, search.max_half_width)))
    config = TapConfig(half_width=half_width, criterion=getattr(search, "criterion", Criterion.MLE))
    try:
        shared, error = (None, None) if model is None else survey_map_error(survey, bathymetry, model)
        if calibration is None:
            fix = tap_fix(survey, bathymetry, index, window, config, prior=prior, shared=shared, error=error,
                          drift=None if model is None else model.tide_drift)
        else:
            fix = _calibrated_fix(survey, bathymetry, index, window, config, prior, shared, error,
                                  calibration, model)
    except MatchingError as exc:
        _log.info("fix at ping %d: %s", index, exc)
        return None, FixRecord.of(index, None, FixStatus.MATCH_FAILED, np.nan, half_width, str(exc))
    status = FixStatus.ACCEPTED if fix.accepted else \
        FixStatus.MULTIMODAL if fix.quality.multimodal else FixStatus.UNINFORMATIVE
    return fix, FixRecord.of(index, fix, status, np.nan, half_width, "; ".join(fix.quality.reasons))


def _calibrated_fix(survey, bathymetry, index, window, config, prior, shared, error, calibration,
                    model) -> TapFix:
    """The TAP fix of a window laid with the calibrated DR, grown by the laying's uncertainty."""
    mean, cov = calibration
    poses, jac = calibrated_window(survey, index, window, mean)
    patch = window_patch(survey, index, window, min_soundings=config.min_soundings, poses=poses,
                         shared=shared, error=error, drift=model.tide_drift)
    fix = tap_fix_patch(patch, bathymetry, config, prior=prior)
    grown = fix.covariance + shape_covariance(survey, model.dead_reckoning, fix.first, fix.index, jac, cov)
    return dataclasses.replace(fix, covariance=0.5 * (grown + grown.T))


@dataclasses.dataclass(frozen=True, eq=False)
class HeldFix:
    """A surprising fix waiting to be confirmed (:func:`decide_fix`): the ``fix``, the ping
    ``index`` it ends at, the fix ``attempts`` made since, and for a particle filter the
    ``anchor (N, 2)``: each particle's position then (its displacement since is the dead
    reckoning's, whatever the weights did; resampling takes it along, :meth:`take`), and its
    ``record`` (:func:`decided` settles it)."""

    fix: TapFix
    index: int
    attempts: int = 0
    anchor: np.ndarray | None = None
    record: FixRecord | None = None

    def take(self, index: np.ndarray) -> HeldFix:
        """The same held fix after the particles were resampled to ``index``."""
        anchor = None if self.anchor is None else self.anchor[index]
        return dataclasses.replace(self, anchor=anchor)


class FixDecision(NamedTuple):
    """What :func:`decide_fix` decided: ``action`` (``"use"``, ``"hold"``, ``"confirm"``: use
    this fix, which confirms the held one, or ``"wait"``: use nothing, the held fix waits), the
    ``held`` fix after it, the fix's ``nis`` against the prediction and the held fix ``dropped``
    unconfirmed (None: none)."""

    action: str
    held: HeldFix | None
    nis: float
    dropped: HeldFix | None = None


def decide_fix(
    fix: TapFix,
    index: int,
    prediction: np.ndarray,
    covariance: np.ndarray,
    held: HeldFix | None,
    displacement: tuple[np.ndarray, np.ndarray] | None,
    config,
    *,
    half_width: float,
) -> FixDecision:
    """What to do with the accepted ``fix`` of the window ending at ping ``index`` (see the module
    docstring): ``prediction`` and ``covariance`` are the predicted position and its covariance,
    ``held`` the fix waiting to be confirmed and ``displacement`` the mean ``(2,)`` and covariance
    ``(2, 2)`` of the dead-reckoned displacement since it was held (None without one). ``config``
    gives ``confirm_probability`` (None: every fix is used at once) and ``gate`` (a confirming
    fix's NIS against the held fix moved by the DR) and ``search_sigmas``; ``half_width`` is the
    search's (m): only a fix precise for it (:func:`tangraph.geometry.is_precise`) confirms, and a
    vague one that agrees with the held fix and is as surprising lets it ``"wait"`` (neither is
    used: it says the prediction is wrong, not where the vehicle is). Pure: nothing is changed."""
    nis = float(mahalanobis2(fix.position - prediction, covariance + fix.covariance))
    if config.confirm_probability is None:
        return FixDecision("use", None, nis)
    surprising = nis > gate_threshold(config.confirm_probability)
    if held is not None:
        assert displacement is not None  # given with a held fix
        shift, spread = displacement
        error = fix.position - (held.fix.position + shift)
        agrees = float(mahalanobis2(error, held.fix.covariance + spread + fix.covariance)) <= config.gate
        if agrees and surprising:
            if is_precise(fix.covariance, half_width, config.search_sigmas):
                return FixDecision("confirm", None, nis)
            return FixDecision("wait", waited(held), nis)
        if agrees:  # with the held fix and the prediction alike: it tells them apart no more
            return FixDecision("use", waited(held), nis)
    dropped = held
    if not surprising:
        return FixDecision("use", None, nis, dropped)
    return FixDecision("hold", HeldFix(fix, int(index)), nis, dropped)


_STATUS = {"use": FixStatus.ACCEPTED, "confirm": FixStatus.ACCEPTED, "hold": FixStatus.HELD,
           "wait": FixStatus.VAGUE}


def decided(record: FixRecord, decision: FixDecision, held: HeldFix | None,
            detail: str = "") -> tuple[tuple[FixRecord, ...], HeldFix | None]:
    """The records that ``decision`` on the fix of ``record`` writes (the held fix's first, when it
    settled it: ``CONFIRMED``, or ``UNCONFIRMED`` when dropped or out of attempts) and the held
    fix after it, carrying its record; ``detail`` says what the filter did with a fix it used."""
    if decision.action == "confirm":
        assert held is not None and held.record is not None  # a confirmation needs a held fix
        detail = f"confirms the fix at ping {held.index}" + (f"; {detail}" if detail else "")
    elif decision.action == "hold":
        detail = "surprising: held until a later fix agrees"
    elif decision.action == "wait":
        assert held is not None  # a fix waits for a held one
        detail = f"as surprising as the held fix at ping {held.index}, too vague to confirm it"
    new = dataclasses.replace(record, status=_STATUS[decision.action], nis=decision.nis, detail=detail)
    after = decision.held
    if decision.action == "hold" and after is not None:
        after = dataclasses.replace(after, record=new)
    if decision.action == "confirm":
        return (_settled(held, FixStatus.CONFIRMED, f"by the fix at ping {record.index}"), new), after
    why = f"the fix at ping {record.index} did not agree with it" if decision.dropped is not None else None
    return (*expired(held, after, why), new), after


def expired(before: HeldFix | None, after: HeldFix | None, why: str | None = None) -> tuple[FixRecord, ...]:
    """The held fix's record turned ``UNCONFIRMED`` when it is gone (``after`` is not it): ``why``,
    else no fix confirmed it within :data:`HOLD_ATTEMPTS` attempts; nothing while it waits."""
    if before is None or before.record is None or (after is not None and after.index == before.index):
        return ()
    why = why or f"no fix confirmed it in {HOLD_ATTEMPTS} attempts"
    return (_settled(before, FixStatus.UNCONFIRMED, why),)


def _settled(held: HeldFix | None, status: FixStatus, detail: str) -> FixRecord:
    assert held is not None and held.record is not None
    return dataclasses.replace(held.record, status=status, detail=detail)


def waited(held: HeldFix | None) -> HeldFix | None:
    """The held fix after one more fix attempt that did not settle it: None (dropped) after
    :data:`HOLD_ATTEMPTS` of them."""
    if held is None or held.attempts + 1 >= HOLD_ATTEMPTS:
        return None
    return dataclasses.replace(held, attempts=held.attempts + 1)
