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
   counts as 0; with ``signal_gate`` (default) the constant is multiplied by the share of the
   measured sequence's variance that is terrain, not noise (:func:`signal_share`);
5. estimate (weighted mean and covariance), then resample when ESS < ``ess_threshold * N``
   (default 1.0: every ping, as the paper). The histories follow the particles through
   resampling (indexed by the resampling indices). The calibration kernel moves the DR's
   constant errors in proportion to what each ping's weights told (``kernel_ess``): at its
   full bandwidth at every ping it walked the compass DR's heading error on Lake Caputh to
   100 deg.

**The signal gate.** A correlation between two depth sequences says where the vehicle is only
as far as the sequences follow the terrain. Over a flat seafloor the measured depths along ``L``
pings vary by no more than their noise (the soundings' own and the map's error under them,
the terrain measurement model's variances), every particle's correlation is noise, and
``exp(c rho)`` multiplies the weights by a random factor at every ping: the cloud collapses onto
whichever particles the noise favours and reports it with confidence (on Lake Caputh's flat
shelf, a 7-minute run with a DR 0.2 m off ended 15 m off with an ANEES of 75; without the
correction, 4 m with an ANEES of 0.3). The gate weighs the correlation by ``S / (S + N)``,
``S`` the measured sequence's variance beyond the noise ``N`` of one ping's mean depth: 1 where
the terrain dominates (the paper's sparse soundings over a varied chart), 0 where the sequence
is noise, as MBARI's modified weighting gives the terrain likelihood its exponent
(:func:`tangraph.sensors.information_exponent`). ``signal_gate=False`` keeps the paper's kernel
as published.

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

__all__ = ["SJCPFConfig", "correlation_log_weight", "signal_share", "sjcpf", "sjcpf_step"]


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
    signal_gate : bool
        Multiply ``c`` by the share of the measured depths' variance over the window that is
        terrain, not noise (module docstring; False: the paper's kernel as published).
    """

    n_particles: int = 1000
    ess_threshold: float = 1.0
    jitter_std: float | None = None
    jitter_fraction: float = 0.15
    window: int = 10
    correlation: Correlation = Correlation.PEARSON
    kernel: Literal["exponential", "power"] = "exponential"
    kernel_constant: float = 2.0
    signal_gate: bool = True

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.jitter_std is not None:
            check_number(self, "jitter_std")
        check_number(self, "jitter_fraction")
        check_number(self, "kernel_constant")
        if not isinstance(self.signal_gate, (bool, np.bool_)):
            raise TangraphError(f"SJCPFConfig.signal_gate must be true or false, got {self.signal_gate!r}")
        object.__setattr__(self, "signal_gate", bool(self.signal_gate))
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


def signal_share(measured: np.ndarray, noise: float) -> float:
    """``S / (S + N)``: the share of the variance of the ``measured (L,)`` depth sequence that
    is terrain, ``S`` its sample variance less ``N = noise`` (the variance of one element's
    error; m^2), at least 0; 1 with no noise (module docstring).

    Examples
    --------
    >>> round(signal_share(np.array([10.0, 12.0, 14.0, 16.0]), 0.0), 6)
    1.0
    >>> signal_share(np.array([10.0, 10.1, 9.9, 10.0]), 0.04)  # flat: the noise alone
    0.0
    >>> round(signal_share(np.array([10.0, 12.0, 14.0, 16.0]), 6.0 + 2.0 / 3.0), 6)
    0.0
    """
    if noise <= 0:
        return 1.0
    s = max(float(np.var(measured, ddof=1)) - noise, 0.0)
    return s / (s + noise)


def _ping_noise(ping: Ping, model: FilterModel) -> float:
    """The variance (m^2) of the error of a ping's mean depth against the map at the truth: its
    soundings' variances (noise and the map error they share) over their count."""
    if ping.variance is None:
        return model.terrain.sounding_std**2 / max(ping.n_soundings, 1)
    return float(np.mean(ping.variance)) / max(ping.n_soundings, 1)


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
            constant = config.kernel_constant
            if config.signal_gate:
                constant *= signal_share(weighted.measured, _ping_noise(ping, model))
            log_f = correlation_log_weight(rho, config.kernel, constant)
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
