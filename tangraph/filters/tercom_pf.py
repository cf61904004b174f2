"""TERCOM-PF: batch TERCOM fixes as the measurements of a particle filter.

The particles move with the shared motion model at every ping; their only measurement is a
batch TERCOM fix (:mod:`tangraph.filters.fixes`: the TAP grid search of
:func:`tangraph.matching.tap_fix`, criterion ``"mle"`` (tide removed; default) or ``"msd"``)
of the window of the last ``window`` pings, searched every ``fix_interval`` pings (default
``window``: the windows do not overlap, so no sounding is used twice) around the cloud's
predicted mean, over ``search_sigmas`` times its std. What a fix does:

- a fix that is not accepted (``TapFix.accepted``: informative and unimodal) or could not be
  made does nothing (``meta["n_fixes_rejected"]``);
- the **first** accepted fix initialises the cloud: the particles are re-drawn from
  ``N(fix, R)``, ``R`` the fix's covariance (before it the cloud is the dead-reckoned prior);
- a later accepted fix whose squared Mahalanobis distance to the predicted mean, under ``P + R``
  (``P`` the cloud's covariance), exceeds ``gate`` (default 13.8, chi2(2) at 0.999) re-centres
  the cloud: the particles are re-drawn from ``N(fix, R)`` (``meta["n_recentred"]``);
- otherwise the particles are re-weighted by the fix's Gaussian likelihood
  ``exp(-(x - fix)^T R^-1 (x - fix) / 2)``, then resampled if ESS < ``ess_threshold * N``.

The particles carry the constant DR errors ``(k, b)`` and move by their calibrated increments
as in every filter; a fix re-weights them by position only, so the calibration is learnt through
its correlation with the position (a re-drawn cloud keeps its particles' calibrations). The
per-ping terrain likelihood is not used by the step (the soundings enter through the fixes
only, and the fix estimates the tide itself), so the model's sounding std and tide prior do not
affect it; they are used only by the divergence recovery of
:func:`~tangraph.filters.run_particle_filter`, which weights a re-drawn cloud by the ping's
terrain likelihood. No terrain update, no :class:`~tangraph.filters.Innovation`: TERCOM-PF
never reports itself lost (a rejected fix is counted instead).
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np

from tangraph.filters.belief import Belief, weighted_moments
from tangraph.filters.config import ParticleConfig, check_number
from tangraph.filters.fixes import attempt_fix, check_fix_search, fix_due, fix_window
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.steps import StepResult, predict, resample_if_needed, reweight
from tangraph.geometry import mahalanobis2
from tangraph.maps.grid import BathymetryMap
from tangraph.matching import Criterion
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["TercomPFConfig", "tercom_pf", "tercom_pf_step"]


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
    gate : float
        Squared Mahalanobis distance beyond which an accepted fix re-centres the cloud.
    """

    window: int | None = None
    fix_interval: int | None = None
    criterion: Criterion = Criterion.MLE
    search_sigmas: float = 3.0
    min_half_width: float | None = None
    max_half_width: float = 1000.0
    gate: float = 13.8

    def __post_init__(self) -> None:
        super().__post_init__()
        check_fix_search(self)
        check_number(self, "gate", open_low=True)


def _draw(centre: np.ndarray, covariance: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    chol = np.linalg.cholesky(covariance + 1e-9 * np.eye(2))
    return centre + rng.standard_normal((n, 2)) @ chol.T


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
    )  # fmt: skip
    counts = {"n_fixes_accepted": 0, "n_fixes_rejected": 0, "n_recentred": 0}
    if fix is None or not fix.accepted:
        counts["n_fixes_rejected"] = 1
        mean, cov = prior_mean, prior_cov
        new, index, ess = resample_if_needed(moved, config, rng=rng, model=model)
        return StepResult(new, mean, cov, ess, resampled=index is not None, counts=counts, fixes=(record,))
    counts["n_fixes_accepted"] = 1
    r = fix.covariance
    d = fix.position - prior_mean
    distance2 = float(mahalanobis2(d, prior_cov + r))
    record["mahalanobis2"] = distance2
    n = moved.n_particles
    if moved.n_fixes == 0 or distance2 > config.gate:
        action = "initialise" if moved.n_fixes == 0 else "recentre"
        counts["n_recentred"] = int(action == "recentre")
        updated = moved.replace(
            particles=_draw(fix.position, r, n, rng),
            log_weights=np.full(n, -np.log(n)),
            n_fixes=moved.n_fixes + 1,
        )
    else:
        action = "reweight"
        e = moved.particles - fix.position
        log_factor = -0.5 * mahalanobis2(e, r)
        updated = reweight(moved, log_factor, where=f"ping {ping.index} (fix)").replace(
            n_fixes=moved.n_fixes + 1
        )
    record["action"] = action
    mean, cov = weighted_moments(updated)
    new, index, ess = resample_if_needed(updated, config, rng=rng, model=model)
    return StepResult(new, mean, cov, ess, resampled=index is not None, counts=counts, fixes=(record,))


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
    the module docstring. ``meta["fixes"]`` records every fix attempted."""
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
        count_keys=("n_fixes_accepted", "n_fixes_rejected", "n_recentred"),
    )
