"""The bootstrap particle filter on the shared terrain likelihood.

Motion model: the particles move by the dead-reckoned displacement between pings plus Gaussian
process noise (``PFConfig.process_std`` metres per ping, per axis); measurement model: the
:class:`~tangraph.filters.likelihood.TerrainLikelihood` of the ping's soundings, placed around
each particle with the dead-reckoned heading. The loop runs over time only; every step is
vectorised over particles and soundings.
"""

from __future__ import annotations

import dataclasses
import time as _time

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.likelihood import TerrainLikelihood, effective_sample_size, log_normalise
from tangraph.filters.resampling import Resampler, resample
from tangraph.maps.grid import BathymetryMap
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["PFConfig", "bootstrap_pf"]


@dataclasses.dataclass(frozen=True)
class PFConfig:
    """Settings of the bootstrap particle filter."""

    n_particles: int = 1000
    init_std: float = 50.0  # m, spread of the initial cloud around the first DR position
    process_std: float = 1.0  # m per ping and axis
    sounding_std: float = 1.0  # m, std of a sounding's error in the likelihood
    tide: float = 0.0  # m, measured = map + tide
    resampler: Resampler = Resampler.SYSTEMATIC
    ess_threshold: float = 0.5  # resample when ESS < threshold * N

    def __post_init__(self) -> None:
        if int(self.n_particles) < 1:
            raise TangraphError(f"PFConfig: n_particles must be at least 1, got {self.n_particles!r}")
        for name in ("init_std", "process_std", "sounding_std"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0) or (name == "sounding_std" and value == 0):
                raise TangraphError(
                    f"PFConfig: {name} must be a non-negative number (sounding_std > 0), got {value!r}"
                )
        if not 0 <= self.ess_threshold <= 1:
            raise TangraphError(f"PFConfig: ess_threshold must lie in [0, 1], got {self.ess_threshold!r}")
        object.__setattr__(self, "resampler", Resampler(self.resampler))


def bootstrap_pf(
    survey: Survey, bathymetry: BathymetryMap, config: PFConfig | None = None, *, rng: np.random.Generator
) -> Track:
    """Run the bootstrap PF over a survey; returns the weighted mean track with its covariance.

    The heading is the dead-reckoned one (its variance is NaN in the track). A step where every
    particle has zero likelihood raises :class:`~tangraph.filters.likelihood.FilterDivergence`
    naming the ping.
    """
    config = config or PFConfig()
    n = int(config.n_particles)
    likelihood = TerrainLikelihood(bathymetry, config.sounding_std, config.tide)
    dr = survey.dr_pose
    north, east = survey.footprints()
    particles = dr[0, :2] + config.init_std * rng.standard_normal((n, 2))
    logw = np.full(n, -np.log(n))
    mean = np.empty((survey.n_pings, 2))
    cov = np.full((survey.n_pings, 3, 3), np.nan)
    ess = np.empty(survey.n_pings)
    n_resampled = 0
    started = _time.perf_counter()
    for k in range(survey.n_pings):
        if k > 0:
            particles = (
                particles + (dr[k, :2] - dr[k - 1, :2]) + config.process_std * rng.standard_normal((n, 2))
            )
        valid = np.isfinite(survey.beam_depth[k])
        if valid.any():
            offsets = np.column_stack([north[k, valid] - dr[k, 0], east[k, valid] - dr[k, 1]])
            logw = logw + likelihood.log_likelihood(particles, offsets, survey.beam_depth[k, valid])
        weights, _ = log_normalise(logw, where=f"ping {k}")
        mean[k] = weights @ particles
        d = particles - mean[k]
        cov[k, :2, :2] = (weights[:, None] * d).T @ d
        ess[k] = effective_sample_size(weights)
        if ess[k] < config.ess_threshold * n:
            particles = particles[resample(weights, config.resampler, rng=rng)]
            logw = np.full(n, -np.log(n))
            n_resampled += 1
        else:
            logw = np.log(np.maximum(weights, np.finfo(float).tiny))
    elapsed = _time.perf_counter() - started
    pose = np.column_stack([mean, dr[:, 2]])
    return Track(
        time=survey.time,
        pose=pose,
        covariance=cov,
        method="pf",
        timings={"total": elapsed, "per_step": elapsed / survey.n_pings},
        meta={
            "ess": ess.tolist(),
            "n_resampled": n_resampled,
            "config": {
                k: (v.value if isinstance(v, Resampler) else v) for k, v in dataclasses.asdict(config).items()
            },
        },
    )
