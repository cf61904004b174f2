"""Particle-filter front ends on one shared motion model and terrain likelihood (no gtsam here).

:func:`run_filter` runs any of them by :class:`FilterMethod`: the bootstrap PF, Han et al.'s IPF,
Chen & Che's SJCPF, the jittered JBPF, TERCOM-PF, grid-search MLE fixes and the point-mass
filter (a grid, no particles), on the survey's :class:`~tangraph.sensors.NavigationModel`
(``model=``; None: from the survey). The filters carry the DR's constant errors (speed scale,
heading error) and every track reports their estimate (``meta["calibration"]``); configs hold
algorithm settings only.
"""

from tangraph.filters.api import FilterMethod, config_type, default_config, run_filter
from tangraph.filters.belief import (
    Belief,
    calibration_estimate,
    initial_belief,
    model_belief,
    state_moments,
    weighted_moments,
)
from tangraph.filters.config import ParticleConfig
from tangraph.filters.correlation import (
    Correlation,
    correlate_rows,
    kendall_rows,
    pearson_rows,
    spearman_rows,
)
from tangraph.filters.ipf import IPFConfig, ipf, ipf_step
from tangraph.filters.jbpf import JBPFConfig, jbpf, jbpf_step
from tangraph.filters.likelihood import (
    FilterDivergence,
    OffMap,
    TerrainLikelihood,
    effective_sample_size,
    log_normalise,
)
from tangraph.filters.mle import MLEConfig, mle_filter
from tangraph.filters.model import FilterModel, MotionModel, Ping, TerrainModel, TerrainUpdate, survey_pings
from tangraph.filters.pf import PFConfig, bootstrap_pf, pf_step
from tangraph.filters.pmf import PMFConfig, point_mass_filter
from tangraph.filters.resampling import Resampler, resample
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.sjcpf import SJCPFConfig, correlation_log_weight, sjcpf, sjcpf_step
from tangraph.filters.steps import (
    Innovation,
    Measurement,
    StepResult,
    jitter,
    measure,
    predict,
    resample_belief,
    resample_if_needed,
    reweight,
    shrink_calibration,
    shrink_state,
)
from tangraph.filters.tercom_pf import TercomPFConfig, tercom_pf, tercom_pf_step

__all__ = [
    "Belief",
    "Correlation",
    "FilterDivergence",
    "FilterMethod",
    "FilterModel",
    "IPFConfig",
    "Innovation",
    "JBPFConfig",
    "MLEConfig",
    "Measurement",
    "MotionModel",
    "OffMap",
    "PFConfig",
    "PMFConfig",
    "ParticleConfig",
    "Ping",
    "Resampler",
    "SJCPFConfig",
    "StepResult",
    "TercomPFConfig",
    "TerrainLikelihood",
    "TerrainModel",
    "TerrainUpdate",
    "bootstrap_pf",
    "calibration_estimate",
    "config_type",
    "correlate_rows",
    "correlation_log_weight",
    "default_config",
    "effective_sample_size",
    "initial_belief",
    "ipf",
    "ipf_step",
    "jbpf",
    "jbpf_step",
    "jitter",
    "kendall_rows",
    "log_normalise",
    "measure",
    "mle_filter",
    "model_belief",
    "pearson_rows",
    "pf_step",
    "point_mass_filter",
    "predict",
    "resample",
    "resample_belief",
    "resample_if_needed",
    "reweight",
    "run_filter",
    "run_particle_filter",
    "shrink_calibration",
    "shrink_state",
    "sjcpf",
    "sjcpf_step",
    "spearman_rows",
    "state_moments",
    "survey_pings",
    "tercom_pf",
    "tercom_pf_step",
    "weighted_moments",
]
