"""The jittered bootstrap particle filter (JBPF): roughening after resampling only.

A bootstrap PF (:func:`~tangraph.filters.pf.pf_step`) that, on the pings where it resamples,
moves every resampled particle by an independent Gaussian jitter of std ``jitter_std`` (m, per
axis) so that copies of one parent separate; pings without resampling are plain bootstrap steps.
The estimate is taken before resampling and jitter, as in the bootstrap PF. It is the control
of SJCPF's "jitter every particle every ping".
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.filters.belief import Belief
from tangraph.filters.config import ParticleConfig
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.pf import pf_step
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.steps import StepResult, jitter
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tangraph.track import Track
from tangraph.validation import check_number

__all__ = ["JBPFConfig", "jbpf", "jbpf_step"]


@dataclasses.dataclass(frozen=True)
class JBPFConfig(ParticleConfig):
    """Settings of the JBPF: those of :class:`~tangraph.filters.ParticleConfig` plus
    ``jitter_std`` (m per axis, applied after each resampling)."""

    jitter_std: float = 2.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_number(self, "jitter_std")


def jbpf_step(
    belief: Belief, ping: Ping, model: FilterModel, config: JBPFConfig, *, rng: np.random.Generator
) -> StepResult:
    """One JBPF step: a bootstrap step (:func:`~tangraph.filters.pf.pf_step`) whose resampled
    particles are then jittered."""
    result = pf_step(belief, ping, model, config, rng=rng)
    if not result.resampled:
        return result
    return dataclasses.replace(result, belief=jitter(result.belief, config.jitter_std, rng=rng))


def jbpf(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: JBPFConfig | None = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator,
    progress: bool = False,
) -> Track:
    """Run the JBPF over a survey (``model``: the navigation model, None: from the survey); see
    the module docstring."""
    return run_particle_filter(
        survey, bathymetry, config or JBPFConfig(), jbpf_step, method="jbpf", rng=rng, model=model,
        progress=progress,
    )  # fmt: skip
