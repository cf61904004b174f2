"""Chen & Che (2022): the particle filter with self-jitter and correlation correction (SJCPF).

Each ping (SEEDS.md section 3):

1. move every particle by the dead-reckoned increment plus the process noise **and** a Gaussian
   jitter of std ``jitter_std`` (the paper's extra process noise of variance 225 m^2: 15 m; by
   default ``jitter_fraction`` = 15 % of the dead-reckoned distance of the ping, which is the
   paper's 15 m at its 100 m between soundings and scales to multibeam pings a few metres apart),
   every particle, every ping;
2. weight by the terrain likelihood of the ping, as the bootstrap PF;
3. append each particle's predicted depth (the mean over the ping's soundings of map depth plus
   tide at the particle: one value per ping for a single beam) to its history, and the measured
   mean depth to the measured history; pings without soundings append nothing;
4. once ``window`` (``L``) depths are recorded, multiply each weight by a kernel ``f(rho_i)`` of
   the correlation ``rho_i`` (``correlation``: Pearson, Spearman or Kendall tau-b) between the
   particle's last ``L`` predicted depths and the last ``L`` measured ones; ``f`` is
   ``exp(kernel_constant * rho)`` (``kernel="exponential"``, the paper's) or
   ``((1 + rho) / 2) ** kernel_constant`` (``"power"``); an undefined rho (a constant sequence)
   counts as 0;
5. estimate (weighted mean and covariance), then resample when ESS < ``ess_threshold * N``
   (default 1.0: every ping, as the paper). The histories follow the particles through
   resampling (indexed by the resampling indices).

The paper gives no particle count, kernel constant or window for its Table 1; the defaults here
(1000 particles, ``exp(2 rho)``, ``L = 10``) are choices to sweep (the null scatter of rho over 10
points is about 1/3, so ``exp(2 rho)`` changes a weight by about a factor 2 per standard error).
The model (sounding std, tide prior, DR errors) is the run's navigation model, as for every
filter (from a chen2022 survey: a sounding std of 1.5 x its 5 m depth noise).
"""

from __future__ import annotations

import dataclasses
from typing import Literal

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.belief import Belief, weighted_moments
from tangraph.filters.config import ParticleConfig
from tangraph.filters.correlation import Correlation, correlate_rows
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.steps import StepResult, measure, predict, resample_if_needed, reweight
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tangraph.track import Track
from tangraph.validation import check_count, check_number

__all__ = ["SJCPFConfig", "correlation_log_weight", "sjcpf", "sjcpf_step"]


@dataclasses.dataclass(frozen=True)
class SJCPFConfig(ParticleConfig):
    """Settings of the SJCPF: those of :class:`~tangraph.filters.ParticleConfig` plus

    Parameters
    ----------
    jitter_std : float or None
        Std (m, per axis) of the jitter added to every particle at every ping (paper: 15 m).
        None: ``jitter_fraction`` times the ping's dead-reckoned distance.
    jitter_fraction : float
        See ``jitter_std``.
    window : int
        Length ``L`` of the depth sequences correlated (>= 3).
    correlation : Correlation
        ``"pearson"``, ``"spearman"`` or ``"kendall"``.
    kernel : {"exponential", "power"}
        ``f(rho) = exp(c rho)`` or ``((1 + rho) / 2) ** c``.
    kernel_constant : float
        The kernel's ``c`` (>= 0; 0 turns the correction off).
    """

    n_particles: int = 1000
    ess_threshold: float = 1.0
    jitter_std: float | None = None
    jitter_fraction: float = 0.15
    window: int = 10
    correlation: Correlation = Correlation.PEARSON
    kernel: Literal["exponential", "power"] = "exponential"
    kernel_constant: float = 2.0

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.jitter_std is not None:
            check_number(self, "jitter_std")
        check_number(self, "jitter_fraction")
        check_number(self, "kernel_constant")
        check_count(self, "window", low=3)
        if self.kernel not in ("exponential", "power"):
            raise TangraphError(f"SJCPFConfig.kernel must be exponential or power, got {self.kernel!r}")
        try:
            object.__setattr__(self, "correlation", Correlation(self.correlation))
        except ValueError:
            raise TangraphError(
                f"SJCPFConfig.correlation must be pearson, spearman or kendall, got {self.correlation!r}"
            ) from None


def correlation_log_weight(rho: np.ndarray, kernel: str, constant: float) -> np.ndarray:
    """``log f(rho)`` of the SJCPF kernel; NaN rho counts as 0.

    Examples
    --------
    >>> correlation_log_weight(np.array([1.0, 0.0, np.nan]), "exponential", 5.0).tolist()
    [5.0, 0.0, 0.0]
    """
    rho = np.asarray(rho, dtype=np.float64)
    rho = np.where(np.isnan(rho), 0.0, rho)
    if kernel == "exponential":
        return constant * rho
    with np.errstate(divide="ignore"):
        return constant * np.log(np.clip((1.0 + rho) / 2.0, 0.0, 1.0))


def _push(history: np.ndarray, column: np.ndarray) -> np.ndarray:
    return np.concatenate([history[..., 1:], column[..., None]], axis=-1)


def sjcpf_step(
    belief: Belief, ping: Ping, model: FilterModel, config: SJCPFConfig, *, rng: np.random.Generator
) -> StepResult:
    """One SJCPF step (see the module docstring)."""
    jitter = config.jitter_std
    if jitter is None:
        jitter = config.jitter_fraction * float(np.hypot(*ping.increment))
    moved = predict(belief, ping, model, rng=rng, extra_std=jitter)
    measured = measure(moved, ping, model, config, rng=rng)
    weighted, update = measured.belief, measured.update
    if update is not None:
        weighted = weighted.replace(
            history=_push(weighted.history, update.predicted),
            measured=_push(weighted.measured, np.array(np.mean(ping.depths))),
            n_history=min(weighted.n_history + 1, config.window),
        )
        if weighted.n_history >= config.window and config.kernel_constant > 0:
            rho = correlate_rows(weighted.history, weighted.measured, config.correlation)
            log_f = correlation_log_weight(rho, config.kernel, config.kernel_constant)
            weighted = reweight(weighted, log_f, where=f"ping {ping.index} (correlation)")
    mean, cov = weighted_moments(weighted)
    new, index, ess = resample_if_needed(weighted, config, rng=rng, model=model)
    return StepResult(
        new, mean, cov, ess, resampled=index is not None,
        counts={"n_tempered": int(measured.tempered), "n_gated": int(measured.gated)},
        info={"ancestors": index, "exponents": measured.exponents}, innovation=measured.innovation,
    )  # fmt: skip


def sjcpf(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: SJCPFConfig | None = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator,
    progress: bool = False,
) -> Track:
    """Run the SJCPF (Chen & Che 2022) over a survey (``model``: the navigation model, None:
    from the survey); see the module docstring."""
    config = config or SJCPFConfig()
    return run_particle_filter(
        survey,
        bathymetry,
        config,
        sjcpf_step,
        method="sjcpf",
        rng=rng,
        model=model,
        progress=progress,
        history_length=config.window,
    )
