"""The bootstrap particle filter on the shared model.

Each ping: move every particle by its calibrated dead-reckoned increment plus the white DR
noise (:class:`~tangraph.filters.model.MotionModel`), multiply its weight by the terrain likelihood of
the ping's soundings turned by its heading error (:class:`~tangraph.filters.model.TerrainModel`;
tempered when too peaked, :func:`~tangraph.filters.steps.measure`), take the weighted mean and
covariance, and resample when the effective sample size falls below ``ess_threshold * N`` (the
calibrations then moved by the shrinkage kernel, :func:`~tangraph.filters.steps.shrink_calibration`).
The loop runs over time only; every step is vectorised over particles and soundings.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.filters.belief import Belief, weighted_moments
from tangraph.filters.config import ParticleConfig
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.steps import StepResult, measure, predict, resample_if_needed
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["PFConfig", "bootstrap_pf", "pf_step"]


@dataclasses.dataclass(frozen=True)
class PFConfig(ParticleConfig):
    """Settings of the bootstrap PF: those of :class:`~tangraph.filters.ParticleConfig`.

    Examples
    --------
    >>> PFConfig(n_particles=500).n_particles
    500
    >>> PFConfig(n_particles=0)
    Traceback (most recent call last):
    ...
    tangraph.errors.TangraphError: PFConfig.n_particles must be an integer >= 1, got 0
    """


def pf_step(
    belief: Belief, ping: Ping, model: FilterModel, config: ParticleConfig, *, rng: np.random.Generator
) -> StepResult:
    """One bootstrap-PF step: predict, weight by the ping (tempered if needed), estimate,
    resample if needed."""
    moved = predict(belief, ping, model, rng=rng)
    measured = measure(moved, ping, model, config, rng=rng)
    weighted = measured.belief
    mean, cov = weighted_moments(weighted)
    new, index, ess = resample_if_needed(weighted, config, rng=rng, model=model)
    info = {"exponents": measured.exponents, "stage_ess": measured.stage_ess}
    return StepResult(
        new, mean, cov, ess, resampled=index is not None,
        counts={"n_tempered": int(measured.tempered), "n_gated": int(measured.gated)},
        info=info, innovation=measured.innovation,
    )  # fmt: skip


def bootstrap_pf(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: PFConfig | None = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator,
    progress: bool = False,
) -> Track:
    """Run the bootstrap PF over a survey; returns the weighted-mean track with its covariance.

    ``model`` is the run's navigation model (None: ``NavigationModel.from_survey(survey)``). The
    heading is the dead-reckoned one (its variance is NaN in the track). A step where every
    particle has zero likelihood is a divergence: the cloud is re-drawn around dead reckoning
    (see :func:`~tangraph.filters.runner.run_particle_filter`).
    """
    return run_particle_filter(
        survey, bathymetry, config or PFConfig(), pf_step, method="pf", rng=rng, model=model,
        progress=progress,
    )  # fmt: skip
