"""One entry point over the particle family: :func:`run_filter` by :class:`FilterMethod`."""

from __future__ import annotations

import enum
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.config import PMFConfig
from tangraph.filters.ipf import IPFConfig, ipf
from tangraph.filters.jbpf import JBPFConfig, jbpf
from tangraph.filters.mle import MLEConfig, mle_filter
from tangraph.filters.pf import PFConfig, bootstrap_pf
from tangraph.filters.pmf import point_mass_filter
from tangraph.filters.runner import check_run_inputs
from tangraph.filters.sjcpf import SJCPFConfig, sjcpf
from tangraph.filters.tercom_pf import TercomPFConfig, tercom_pf
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["FilterMethod", "config_type", "default_config", "run_filter"]


class FilterMethod(enum.StrEnum):
    """The filters, by the names the CLI uses (``Track.method`` is the value)."""

    PF = "pf"
    IPF = "ipf"
    SJCPF = "sjcpf"
    JBPF = "jbpf"
    TERCOM_PF = "tercom-pf"
    MLE = "mle"
    PMF = "pmf"


_RUNNERS: dict[FilterMethod, tuple[type, Any]] = {
    FilterMethod.PF: (PFConfig, bootstrap_pf),
    FilterMethod.IPF: (IPFConfig, ipf),
    FilterMethod.SJCPF: (SJCPFConfig, sjcpf),
    FilterMethod.JBPF: (JBPFConfig, jbpf),
    FilterMethod.TERCOM_PF: (TercomPFConfig, tercom_pf),
    FilterMethod.MLE: (MLEConfig, mle_filter),
    FilterMethod.PMF: (PMFConfig, point_mass_filter),
}


def _method(method: FilterMethod | str) -> FilterMethod:
    try:
        return FilterMethod(method)
    except ValueError:
        known = ", ".join(m.value for m in FilterMethod)
        given = repr(method) if isinstance(method, str) else f"of type {type(method).__name__}"
        raise TangraphError(f"unknown filter method {given}; known: {known}") from None


def config_type(method: FilterMethod | str) -> type:
    """The config dataclass of a method (``PFConfig`` for ``"pf"``, ...)."""
    return _RUNNERS[_method(method)][0]


def default_config(method: FilterMethod | str) -> Any:
    """The default configuration of a method.

    Examples
    --------
    >>> default_config("sjcpf").window
    10
    """
    return config_type(method)()


def run_filter(
    method: FilterMethod | str,
    survey: Survey,
    bathymetry: BathymetryMap,
    config: Any = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator | None,
    progress: bool = False,
) -> Track:
    """Run one filter of the particle family over a survey.

    Parameters
    ----------
    method : FilterMethod or str
        ``"pf"``, ``"ipf"``, ``"sjcpf"``, ``"jbpf"``, ``"tercom-pf"``, ``"mle"`` or ``"pmf"``.
    survey, bathymetry
        The run and the prior map.
    config
        The method's own config (``PFConfig``, ``IPFConfig``, ``SJCPFConfig``, ``JBPFConfig``,
        ``TercomPFConfig``, ``MLEConfig``, ``PMFConfig``); None for its defaults. Configs hold algorithm
        settings only.
    model : NavigationModel or None
        What the filter believes about the DR errors (white noise, the speed scale and heading
        bias it estimates), the start uncertainty, the soundings, the map and the tide; None:
        ``NavigationModel.from_survey(survey)`` (a simulated survey's settings).
    rng : numpy.random.Generator
        The source of randomness (the MLE and point-mass filters do not use it: None is accepted
        there).
    progress : bool
        Show a progress bar over the pings.

    Returns
    -------
    Track
        Weighted mean poses (heading: dead reckoning), covariances ``(K, 3, 3)`` with NaN heading
        terms, ``method`` the method's value; ``meta``: ``ess`` (per ping), ``n_resampled``,
        ``n_divergences``, ``divergence_steps``, ``n_lost``, ``lost_steps`` (pings where the
        filter's innovations say it has lost the vehicle), ``calibration`` (``speed_scale``,
        ``speed_scale_std``, ``heading_error`` (rad, DR minus true, at the last ping),
        ``heading_error_std``), ``navigation_model``, ``config``, ``seed`` (of ``rng``, particle
        filters: :func:`~tangraph.filters.runner.rng_seed`) and the method's counts;
        ``timings``: ``total``, ``per_step`` (s).

    Raises
    ------
    TangraphError
        An unknown method, a config of another method's type, a ``survey``, ``bathymetry``,
        ``rng`` or ``model`` of the wrong type (not a :class:`~tangraph.survey.Survey`,
        :class:`~tangraph.maps.grid.BathymetryMap`, :class:`numpy.random.Generator`,
        :class:`~tangraph.sensors.NavigationModel`), or no ``model`` for a survey that records
        no DR model.
    """
    method = _method(method)
    check_run_inputs(
        survey,
        bathymetry,
        rng,
        where=f"run_filter({method.value!r})",
        rng_optional=method in (FilterMethod.MLE, FilterMethod.PMF),
    )
    cls, runner = _RUNNERS[method]
    if config is None:
        config = cls()
    elif type(config) is not cls:
        raise TangraphError(
            f"filter {method.value!r} takes a {cls.__name__} (or None), got {type(config).__name__}"
        )
    return runner(survey, bathymetry, config, model=model, rng=rng, progress=progress)
