"""Particle-filter front ends on one shared motion model and terrain likelihood (no gtsam here).

:func:`run_filter` runs any of them by :class:`FilterMethod`: the bootstrap PF, Han et al.'s IPF,
Chen & Che's SJCPF, the jittered JBPF, TERCOM-PF, grid-search MLE fixes and the point-mass
filter (a grid, no particles), on the survey's :class:`~tangraph.sensors.NavigationModel`
(``model=``; None: from the survey). The filters carry the DR's constant errors (speed scale,
heading error) and every track reports their estimate (``meta["calibration"]``); configs hold
algorithm settings only.

This package exports what running a filter needs: :func:`run_filter` is the one door (each
filter's own function, which it calls, is in the filter's module:
``tangraph.filters.pf.bootstrap_pf`` and so on). The pieces for writing a new one are in its
modules: the shared model (:mod:`tangraph.filters.model`: motion, terrain, pings), the terrain
likelihood (:mod:`tangraph.filters.likelihood`), the particle belief
(:mod:`tangraph.filters.belief`), the steps a filter is built from (:mod:`tangraph.filters.steps`,
each filter's own ``*_step`` in its module), the run loop (:mod:`tangraph.filters.runner`),
resampling (:mod:`tangraph.filters.resampling`) and the SJCPF's correlations
(:mod:`tangraph.filters.correlation`).
"""

from tangraph.filters.api import FilterMethod, config_type, default_config, run_filter
from tangraph.filters.config import FilterHealth, ParticleConfig, PMFConfig
from tangraph.filters.ipf import IPFConfig
from tangraph.filters.jbpf import JBPFConfig
from tangraph.filters.likelihood import FilterDivergence, OffMap
from tangraph.filters.mle import MLEConfig
from tangraph.filters.pf import PFConfig
from tangraph.filters.sjcpf import SJCPFConfig
from tangraph.filters.tercom_pf import TercomPFConfig

__all__ = [
    "FilterDivergence",
    "FilterHealth",
    "FilterMethod",
    "IPFConfig",
    "JBPFConfig",
    "MLEConfig",
    "OffMap",
    "PFConfig",
    "PMFConfig",
    "ParticleConfig",
    "SJCPFConfig",
    "TercomPFConfig",
    "config_type",
    "default_config",
    "run_filter",
]
