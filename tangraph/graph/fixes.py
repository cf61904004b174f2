"""TAP fixes for the graph: the search region from the marginal, the gate, and the fix records.

Each fix is made on the pings of its window only (a slice of the survey), so its cost does not
grow with the length of the mission. It is refused when TAP flags it (``TapFix.accepted`` false:
``"multimodal"`` or ``"uninformative"``), when the match fails (``"match failed: ..."``) or when
its NIS against the predicted marginal exceeds the gate (``"gate"``).
"""

from __future__ import annotations

import dataclasses
from typing import TypeVar

import numpy as np

from tangraph.errors import TangraphError
from tangraph.fix_records import FixRecord, FixStatus
from tangraph.geometry import gate_threshold
from tangraph.graph.config import GraphConfig
from tangraph.graph.factors import check_fix_covariance, nis
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import (
    Criterion,
    MatchingError,
    TapFix,
    TerrainFix,
    shape_covariance,
    tap_fix_patch,
    window_patch,
)
from tangraph.sensors import DeadReckoningModel, NavigationModel
from tangraph.survey import Survey

__all__ = [
    "FixOutcome",
    "LostEpisode",
    "check_tide_drift",
    "fix_drift",
    "fix_name",
    "judge_fix",
    "make_fix",
    "search_half_width",
    "search_step",
    "window_noise",
]


def check_tide_drift(config: GraphConfig, model: NavigationModel) -> NavigationModel:
    """``model``, unless the graph would hold the tide constant while the model says it drifts
    (``tide_drift_std > 0``): refused, naming the setting that settles it, are TAP windows
    whose criterion takes the depths as reduced to the map's datum (``msd``, ``mad``), the one
    tide of a point-mass front end's window and the smoother's terrain on soundings or with the
    map's error field. The online graph's tracking on soundings and its point-mass acquisition
    follow a drift (:mod:`tangraph.graph.online_tide`)."""
    if model.tide_drift is None:
        return model
    drift = (f"the navigation model's tide drifts (tide_drift_std = {model.tide_drift[0]:g} m: its own, "
             "or the map's error_drift)")
    criterion = config.fixes.tap.criterion
    if criterion in (Criterion.MSD, Criterion.MAD):
        raise TangraphError(f"graph: TAP criterion {criterion.value!r} takes the depths as reduced to the "
                            f"map's datum, but {drift}: use criterion 'mle' (each window's tide estimated)")
    held = [f"{name} = {value!r}" for name, value, default in
            (("front_end", config.online.front_end, "tap"),
             ("smoother_terrain", config.batch.smoother_terrain, "fixes")) if value != default]
    if held:
        raise TangraphError(f"graph: {', '.join(held)} holds one tide for the whole survey, but {drift}: "
                            "use the TAP fixes (the defaults), whose windows estimate their own tide, or "
                            "tracking on soundings (terrain = 'soundings'), which follows the drift")
    return model


def fix_drift(model: NavigationModel, config: GraphConfig, time: np.ndarray) -> tuple[float, float] | None:
    """The tide's drift ``(std, time)`` a fix's window is widened by: the model's, its variance
    grown by what the graph's other fixes share of it, the row sum ``sum_j exp(-|j| s / T)`` =
    ``coth(s / 2T)`` of the drift's correlation over fixes every ``s`` seconds (``config``'s fix
    spacing at the survey's median ping interval ``time``), as the terrain model counts the
    map error the soundings share: each fix is added to the graph on its own, and neighbouring
    windows read the same drift (None: a constant tide)."""
    drift = model.tide_drift
    if drift is None:
        return None
    std, forget = drift
    step = config.spacing * float(np.median(np.diff(time))) if time.size > 1 else forget
    shared = 1.0 / np.tanh(step / (2.0 * forget)) if step > 0 else 1.0
    return std * float(np.sqrt(shared)), forget


#: A terrain fix of either front end (:class:`~tangraph.matching.TerrainFix`), kept as its own type.
Fix = TypeVar("Fix", bound=TerrainFix)


def fix_name(fix: TerrainFix) -> str:
    return f"fix at ping {fix.index} (window {fix.first}..{fix.index})"


@dataclasses.dataclass(frozen=True)
class LostEpisode:
    """A time an online navigator was lost (``Track.meta["lost_episodes"]``): from ``start`` (the
    last fix it trusted, or the first ping) through ``declared`` (the window that made it lost)
    to ``end`` (the ping where it relocalised; None if it never did), and the ``breaks``: the
    extra position stds (m) by which it widened its belief."""

    start: int
    declared: int
    end: int | None = None
    breaks: tuple[float, ...] = ()

    def pings(self, n_pings: int) -> range:
        """The pings flagged lost."""
        return range(self.start, n_pings if self.end is None else self.end + 1)

    def as_dict(self) -> dict:
        """JSON-ready form (``breaks`` a list)."""
        return {**dataclasses.asdict(self), "breaks": list(self.breaks)}


@dataclasses.dataclass(frozen=True)
class FixOutcome:
    """What became of one fix: its record for ``Track.fixes`` and the fix judged (with
    the covariance the graph gives it; None when no fix could be made)."""

    record: FixRecord
    fix: TerrainFix | None

    @property
    def accepted(self) -> bool:
        return self.record.accepted


def search_step(config: GraphConfig, bathymetry: BathymetryMap) -> float:
    """Step (m) of the TAP candidate grid: ``tap.step``, else ``tap_step_cells`` map cells."""
    if config.fixes.tap.step is not None:
        return float(config.fixes.tap.step)
    return float(config.fixes.tap_step_cells * min(bathymetry.cell_size))


def search_half_width(config: GraphConfig, bathymetry: BathymetryMap, position_cov) -> float:
    """Half-width (m) of the TAP search around the predicted position
    (``GraphConfig.fixes.half_width_rule``)."""
    if config.fixes.half_width_rule == "fixed":
        return float(config.fixes.tap.half_width)
    cell = float(min(bathymetry.cell_size))
    sigma = float(np.sqrt(max(np.linalg.eigvalsh(np.asarray(position_cov, float)).max(), 0.0)))
    return float(np.clip(config.fixes.half_width_sigmas * sigma, config.fixes.min_half_width_cells * cell,
                         config.fixes.max_half_width_cells * cell))


def window_noise(fix: Fix, survey: Survey, white: DeadReckoningModel, shape_jacobian,
                 calibration_cov, overlap: float) -> Fix:
    """``fix`` with the covariance the graph gives it.

    TAP's covariance counts the information of its window's soundings; windows that share pings
    would count each sounding ``overlap`` times (the mean number of windows holding its pings,
    :func:`~tangraph.graph.keyposes.fix_windows`), so it is multiplied by ``overlap``. The patch
    is laid with the calibrated DR of the current estimate, whose remaining uncertainty grows it
    (:func:`tangraph.matching.shape_covariance` of ``white``, ``shape_jacobian`` and
    ``calibration_cov``).
    """
    grown = max(float(overlap), 1.0) * np.asarray(fix.covariance, float)
    grown = grown + shape_covariance(survey, white, fix.first, fix.index, shape_jacobian, calibration_cov)
    # both front ends' fixes are frozen dataclasses (the protocol cannot say so)
    return dataclasses.replace(fix, covariance=0.5 * (grown + grown.T))  # type: ignore[type-var]


def make_fix(survey: Survey, bathymetry: BathymetryMap, end: int, config: GraphConfig, prior,
             half_width: float, *, poses=None, first: int | None = None, shared=None,
             error=None, drift: tuple[float, float] | None = None) -> TapFix:
    """The TAP fix of the window of pings ``first`` (default ``end - config.fixes.n_pings + 1``) to
    ``end``, searched within ``half_width`` of ``prior``; the patch is laid with ``poses``, the
    poses of the window's pings (default: their DR poses); ``shared (K, B)``: the survey's
    shared map error variances (:func:`tangraph.sensors.shared_map_variances`; None: a perfect
    map), which widen the fix's covariance, ``error`` the map's error, whose part shared
    among the window's soundings widens its regions, and ``drift`` the tide's drift
    (``NavigationModel.tide_drift``: :func:`tangraph.matching.tap_fix`).

    Raises
    ------
    MatchingError
        As :func:`tangraph.matching.tap_fix`.
    """
    first = end - config.fixes.n_pings + 1 if first is None else int(first)
    if first < 0:
        raise MatchingError(f"the window ending at ping {end} starts before the survey ({first})")
    if not np.isfinite(survey.beam_depth[first : end + 1]).any():
        raise MatchingError(f"window of pings {first}..{end} has no sounding")
    patch = window_patch(survey, end, end - first + 1, min_soundings=config.fixes.tap.min_soundings,
                         poses=poses, shared=shared, error=error, drift=drift)
    tap = dataclasses.replace(config.fixes.tap, half_width=float(half_width),
                              step=search_step(config, bathymetry))
    return tap_fix_patch(patch, bathymetry, tap, prior=np.asarray(prior, float))


def failed(index: int, error: Exception, half_width: float,
           status: FixStatus = FixStatus.MATCH_FAILED) -> FixOutcome:
    """The record of a window whose match failed (or whose fix had an invalid covariance)."""
    return FixOutcome(FixRecord.of(index, None, status, np.nan, half_width, str(error)), None)


def judge_fix(fix: TerrainFix, predicted, predicted_cov, config: GraphConfig, half_width: float, *,
              strict: bool = False, noise: float | None = None) -> FixOutcome:
    """Accept or refuse ``fix`` against the predicted position ``(2,)`` and its covariance ``(2, 2)``.

    A fix whose residual std at its best match exceeds ``config.fixes.misfit_ratio`` times ``noise``
    (the residual std it is held against: the navigation model's ``measurement_std``, or the
    online navigator's median of recent windows when larger) is ``MISFIT``: the window's
    soundings fit the map nowhere (a depth bias on part of its pings), which says nothing of
    where the vehicle is. A fix whose best match lies on the edge of the search is
    ``OUTSIDE_SEARCH``; ``strict`` (a lost navigator's relocalisation candidates) refuses a
    multimodal fix whatever ``config.fixes.accept_multimodal`` says.

    Raises
    ------
    TangraphError
        The fix's covariance is not finite, symmetric and positive definite (the fix is named).
    """
    cov = check_fix_covariance(fix.covariance, fix_name(fix))
    value = nis(np.asarray(fix.position, float) - np.asarray(predicted, float)[:2],
                cov + np.asarray(predicted_cov, float)[:2, :2])
    detail = "; ".join(fix.quality.reasons)
    if fix.quality.depth_fault:  # its depths are wrong, not the place: no evidence of being lost
        status = FixStatus.MISFIT
    elif (noise is not None and config.fixes.misfit_ratio is not None
          and fix.sigma > config.fixes.misfit_ratio * noise):
        status = FixStatus.MISFIT
        detail = f"residual std {fix.sigma:.3g} m at the best match, {fix.sigma / noise:.1f} x the model's"
    elif fix.quality.outside:
        status = FixStatus.OUTSIDE_SEARCH
    elif fix.quality.multimodal and (strict or not (config.fixes.accept_multimodal
                                                    and config.fixes.tap.covariance == "region")):
        status = FixStatus.MULTIMODAL
    elif not fix.quality.informative:
        status = FixStatus.UNINFORMATIVE
    elif value > gate_threshold(config.fixes.gate_probability):
        status = FixStatus.GATE
    else:
        status = FixStatus.ACCEPTED
    record = FixRecord.of(fix.index, fix, status, value, half_width, detail)
    return FixOutcome(record, fix)
