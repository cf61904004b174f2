"""TERCOM-PF: batch TERCOM fixes as the measurements of a particle filter.

The particles move with the shared motion model at every ping; their only measurement is a
batch TERCOM fix (:mod:`tangraph.filters.fixes`: the TAP grid search of
:func:`tangraph.matching.tap_fix`, criterion ``"mle"`` (tide removed; default) or ``"msd"``)
of the window of the last ``window`` pings, searched every ``fix_interval`` pings (default
``window``: the windows do not overlap, so no sounding is used twice) around the cloud's
predicted mean, over ``search_sigmas`` times its std. What a fix does:

- a fix that is not accepted (``TapFix.accepted``: informative and unimodal) or could not be
  made does nothing (``meta["n_fixes_rejected"]``);
- ``confirm_probability=None`` (the default) is the plain TERCOM-PF: the first accepted fix
  initialises the cloud (re-drawn from ``N(fix, R)``), a later one beyond ``gate`` of the
  prediction (``P + R``, ``P`` the cloud's covariance) re-centres it, any other re-weights it
  (however few particles carry the weight then);
- with ``confirm_probability`` set, an accepted fix is judged against the cloud's prediction
  (:func:`tangraph.filters.fixes.decide_fix`, the online graph's rule): one within the
  ``confirm_probability`` quantile of its NIS re-weights the particles by its Gaussian
  likelihood ``exp(-(x - fix)^T R^-1 (x - fix) / 2)`` (``R`` the fix's covariance), then they
  are resampled if ESS < ``ess_threshold * N``; when fewer than
  :data:`MIN_FIX_ESS` of them would carry the weight (a cloud far wider than the fix), the
  positions are re-drawn from the Gaussian product of the cloud's moments and the fix instead;
- a surprising fix is held (``meta["n_fixes_held"]``) until a later accepted fix, as surprising
  and precise for its search, agrees with it through the particles' own displacements since
  (NIS within ``gate``, default 13.8: chi2(2) at 0.999); the prediction is then wrong, and the
  cloud is re-centred: its positions re-drawn from ``N(fix, R)`` of the later fix
  (``meta["n_recentred"]``). A held fix that is not confirmed is dropped.

The particles carry the constant DR errors ``(k, b)`` and move by their calibrated increments
as in every filter; a fix re-weights them by position only, so the calibration is learnt through
its correlation with the position (a re-drawn cloud keeps its particles' calibrations). The
per-ping terrain likelihood is not used by the step (the soundings enter through the fixes
only, and the fix estimates the tide itself), so the model's sounding std and tide prior do not
affect it; they are used only by the divergence recovery of
:func:`~tangraph.filters.runner.run_particle_filter`, which weights a re-drawn cloud by the ping's
terrain likelihood. No terrain update, no :class:`~tangraph.filters.steps.Innovation`: TERCOM-PF
never reports itself lost (a rejected fix is counted instead).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from tangraph.filters.belief import Belief, calibration_moments, weighted_moments
from tangraph.filters.config import ParticleConfig
from tangraph.filters.fixes import (
    attempt_fix,
    check_fix_search,
    decide_fix,
    decided,
    expired,
    fix_due,
    fix_window,
    waited,
)
from tangraph.filters.likelihood import effective_sample_size
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.steps import StepResult, predict, resample_if_needed, reweight
from tangraph.fix_records import FixRecord
from tangraph.geometry import mahalanobis2
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import Criterion
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["MIN_FIX_ESS", "TercomPFConfig", "tercom_pf", "tercom_pf_step"]

#: The counts a TERCOM-PF run adds to its track's ``meta``.
COUNTS = ("n_fixes_accepted", "n_fixes_rejected", "n_fixes_held", "n_recentred")


@dataclasses.dataclass(frozen=True)
class TercomPFConfig(ParticleConfig):
    """Settings of TERCOM-PF: those of :class:`~tangraph.filters.ParticleConfig` plus

    Parameters
    ----------
    window : int or None
        Pings per fix (Han et al.: 5). None: enough for about 30 soundings, at least 5
        (:func:`~tangraph.filters.fixes.fix_window`).
    fix_interval : int or None
        Pings between fixes; None: ``window``.
    criterion : Criterion
        ``"mle"`` or ``"msd"``.
    search_sigmas, min_half_width, max_half_width : float
        Search half-width: ``search_sigmas`` times the cloud's std, within
        ``[min_half_width (None: the larger of 3 map cells and the model's initial_position_std),
        max_half_width]`` metres.
    confirm_probability : float or None
        A fix whose NIS against the prediction exceeds the ``chi2(2)`` quantile of this
        probability is held until a later one confirms it (0.9: the online graph's rule); None
        (default): the plain TERCOM-PF. On the scenarios of ``experiments/graph_vs_filters``
        0.9 lowered the mean final NEES on ``demo-map-error`` and ``han2020-map-error`` but was
        no more accurate anywhere, and on the perfect-map ``wang2019`` its cloud drifted after
        a re-weighted first fix in more runs (mean RMSE 25.3 against the plain 19.5 m); the
        default stays the plain method.
    gate : float
        The NIS within which a later fix confirms a held one; with ``confirm_probability=None``,
        the squared Mahalanobis distance beyond which an accepted fix re-centres the cloud.
    """

    window: int | None = None
    fix_interval: int | None = None
    criterion: Criterion = Criterion.MLE
    search_sigmas: float = 3.0
    min_half_width: float | None = None
    max_half_width: float = 1000.0
    confirm_probability: float | None = None
    gate: float = 13.8

    def __post_init__(self) -> None:
        super().__post_init__()
        check_fix_search(self)


#: Fewest effective particles a fix may leave by re-weighting; fewer: the positions are re-drawn.
MIN_FIX_ESS = 0.01


def _draw(centre: np.ndarray, covariance: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    chol = np.linalg.cholesky(covariance + 1e-9 * np.eye(2))
    return centre + rng.standard_normal((n, 2)) @ chol.T


def _redrawn(belief: Belief, centre: np.ndarray, covariance: np.ndarray, rng: np.random.Generator) -> Belief:
    """The belief with its positions re-drawn from ``N(centre, covariance)``, equally weighted
    (each particle keeps its calibration and tide)."""
    n = belief.n_particles
    return belief.replace(particles=_draw(centre, covariance, n, rng), log_weights=np.full(n, -np.log(n)))


def _use(belief: Belief, fix, mean: np.ndarray, cov: np.ndarray, where: str,
         rng: np.random.Generator) -> tuple[Belief, str]:
    """The belief after a fix that is used (see the module docstring) and what was done."""
    log_factor = -0.5 * mahalanobis2(belief.particles - fix.position, fix.covariance)
    weighted = reweight(belief, log_factor, where=where)
    if effective_sample_size(weighted.weights) >= MIN_FIX_ESS * belief.n_particles:
        return weighted, "reweight"
    gain = np.linalg.solve(cov + fix.covariance, cov).T  # the Gaussian product of cloud and fix
    posterior = cov - gain @ cov
    centre = mean + gain @ (fix.position - mean)
    return _redrawn(belief, centre, 0.5 * (posterior + posterior.T), rng), "redraw"


def _displacement(belief: Belief) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean ``(2,)`` and covariance ``(2, 2)`` of the particles' displacements since
    the held fix's anchor."""
    assert belief.held is not None and belief.held.anchor is not None
    return weighted_moments(belief.replace(particles=belief.particles - belief.held.anchor))


def tercom_pf_step(
    belief: Belief,
    ping: Ping,
    model: FilterModel,
    config: TercomPFConfig,
    *,
    rng: np.random.Generator,
    survey: Survey,
    bathymetry: BathymetryMap,
    window: int | None = None,
) -> StepResult:
    """One TERCOM-PF step (see the module docstring); ``window`` defaults to
    :func:`~tangraph.filters.fixes.fix_window` of the config and survey (computed once per survey
    and cached; :func:`tercom_pf` passes it)."""
    window = window or fix_window(config, survey)
    moved = predict(belief, ping, model, rng=rng)
    if not fix_due(config, ping.index, window):
        mean, cov = weighted_moments(moved)
        new, index, ess = resample_if_needed(moved, config, rng=rng, model=model)
        return StepResult(new, mean, cov, ess, resampled=index is not None)
    prior_mean, prior_cov = weighted_moments(moved)
    fix, record = attempt_fix(
        survey, bathymetry, ping.index, prior_mean, prior_cov, config, window,
        initial_std=model.navigation.initial_position_std, model=model.navigation,
        calibration=calibration_moments(moved),
    )  # fmt: skip
    counts = dict.fromkeys(COUNTS, 0)
    if fix is None or not fix.accepted:
        counts["n_fixes_rejected"] = 1
        after = waited(moved.held)
        updated, action, records = moved.replace(held=after), "none", (*expired(moved.held, after), record)
    else:
        counts["n_fixes_accepted"] = 1
        updated, action, records = _judged(moved, fix, record, prior_mean, prior_cov, config, ping.index, rng)
    counts["n_recentred"] = int(action == "recentre")
    counts["n_fixes_held"] = int(action == "hold")
    mean, cov = weighted_moments(updated)
    new, index, ess = resample_if_needed(updated, config, rng=rng, model=model)
    return StepResult(new, mean, cov, ess, resampled=index is not None, counts=counts, fixes=records)


def _judged(moved: Belief, fix, record: FixRecord, mean: np.ndarray, cov: np.ndarray, config: TercomPFConfig,
            index: int, rng: np.random.Generator) -> tuple[Belief, str, tuple[FixRecord, ...]]:
    """The belief after the accepted ``fix`` of ping ``index``, the action taken (see the module
    docstring; the ``detail`` of a fix used) and the records written (the held fix's, when
    settled, then this one's)."""
    if config.confirm_probability is None:  # the plain TERCOM-PF
        nis = float(mahalanobis2(fix.position - mean, cov + fix.covariance))
        if moved.n_fixes == 0 or nis > config.gate:
            action = "initialise" if moved.n_fixes == 0 else "recentre"
            updated = _redrawn(moved, fix.position, fix.covariance, rng)
        else:
            log_factor = -0.5 * mahalanobis2(moved.particles - fix.position, fix.covariance)
            updated, action = reweight(moved, log_factor, where=f"ping {index} (fix)"), "reweight"
        used = dataclasses.replace(record, nis=nis, detail=action)
        return updated.replace(n_fixes=moved.n_fixes + 1), action, (used,)
    displacement = None if moved.held is None else _displacement(moved)
    decision = decide_fix(fix, index, mean, cov, moved.held, displacement, config,
                          half_width=record.half_width)
    if decision.action == "hold":
        records, held = decided(record, decision, moved.held)
        held = dataclasses.replace(held, anchor=moved.particles.copy())  # type: ignore[type-var]
        return moved.replace(held=held), "hold", records
    if decision.action == "wait":  # surprising and agreeing with the held fix, but too vague to confirm it
        records, held = decided(record, decision, moved.held)
        return moved.replace(held=held), "wait", records
    if decision.action == "confirm":
        updated, action = _redrawn(moved, fix.position, fix.covariance, rng), "recentre"
    else:
        updated, action = _use(moved, fix, mean, cov, f"ping {index} (fix)", rng)
    records, held = decided(record, decision, moved.held, action)
    return updated.replace(n_fixes=moved.n_fixes + 1, held=held), action, records


def tercom_pf(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: TercomPFConfig | None = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator,
    progress: bool = False,
) -> Track:
    """Run TERCOM-PF over a survey (``model``: the navigation model, None: from the survey); see
    the module docstring. ``Track.fixes`` records every fix attempted."""
    config = config or TercomPFConfig()
    window = fix_window(config, survey)
    step = functools.partial(tercom_pf_step, survey=survey, bathymetry=bathymetry, window=window)
    return run_particle_filter(
        survey,
        bathymetry,
        config,
        step,
        method="tercom-pf",
        rng=rng,
        model=model,
        progress=progress,
        count_keys=COUNTS,
    )
