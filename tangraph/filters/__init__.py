"""Particle-filter front ends on one shared terrain likelihood (no gtsam here)."""

from tangraph.filters.likelihood import (
    FilterDivergence,
    TerrainLikelihood,
    effective_sample_size,
    log_normalise,
)
from tangraph.filters.pf import PFConfig, bootstrap_pf
from tangraph.filters.resampling import Resampler, resample

__all__ = [
    "FilterDivergence",
    "PFConfig",
    "Resampler",
    "TerrainLikelihood",
    "bootstrap_pf",
    "effective_sample_size",
    "log_normalise",
    "resample",
]
