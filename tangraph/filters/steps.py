"""The pieces of a particle filter's step: prediction, terrain update, resampling, kernels.

A filter is a pure step ``step(belief, ping, model, config, *, rng) -> StepResult`` (:data:`Step`)
built from these: it returns a new :class:`~tangraph.filters.belief.Belief` and never writes into
its inputs.

Honest covariances. The terrain update :func:`measure` tempers a ping whose likelihood is far
narrower than the cloud (progressive correction: exponents summing to 1, each the largest that
keeps the ESS at or above ``tempering_ess`` times the ESS before it; resampling and the shrinkage
kernel between stages), and the sounding variance it uses includes the map error. After every
resampling the calibration ``(k, b)`` is moved by a Liu-West shrinkage kernel conditional on the
position (:func:`shrink_calibration`), which keeps the cloud's mean and covariance but lets the
constant errors take new values (they have no process noise, ``b`` at most its walk).

Every ping with soundings gives an :class:`Innovation` (the runner's lost test,
:mod:`tangraph.filters.runner`); with ``FilterHealth.ping_gate`` an inconsistent ping does
not weigh the cloud (:func:`gated`).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from typing import Any, cast

import numpy as np
from scipy import special, stats

from tangraph.filters.belief import Belief, state_moments
from tangraph.filters.config import ParticleConfig
from tangraph.filters.likelihood import OffMap, PingLikelihood, effective_sample_size, log_normalise
from tangraph.filters.model import FilterModel, Ping, TerrainUpdate
from tangraph.filters.resampling import Resampler, resample
from tangraph.filters.tide import predict_tide
from tangraph.fix_records import FixRecord

__all__ = [
    "Innovation",
    "Measurement",
    "Step",
    "StepResult",
    "evaluate",
    "gated",
    "innovation",
    "jitter",
    "kernel_bandwidth",
    "measure",
    "predict",
    "resample_belief",
    "resample_if_needed",
    "reweight",
    "shrink_calibration",
    "shrink_state",
]


@dataclasses.dataclass(frozen=True, eq=False)
class StepResult:
    """One step's output: the new belief, the estimate (mean, covariance), the ESS of the weights
    the estimate is taken from (the Monte Carlo error of the estimate depends on them),
    whether it resampled, counts summed into the track's metadata, fix records (TERCOM-PF), the
    ping's :class:`Innovation` (None without a terrain update) and ``info`` for inspection (not
    recorded)."""

    belief: Belief
    mean: np.ndarray
    covariance: np.ndarray
    ess: float
    resampled: bool = False
    counts: dict[str, int] = dataclasses.field(default_factory=dict)
    fixes: tuple[FixRecord, ...] = ()
    info: dict[str, Any] = dataclasses.field(default_factory=dict)
    innovation: Innovation | None = None


@dataclasses.dataclass(frozen=True)
class Innovation:
    """How well the predicted cloud explains a ping of ``n_soundings`` soundings: ``nis``, the
    squared innovation of the mean sounding over its predictive variance (the weighted cloud's
    spread of predicted mean depths, plus ``sigma^2 / B`` and the tide variance; chi-square(1)
    when the model holds), and ``best_chi2``, the smallest ``-2 log p`` over the particles
    (chi-square(B) at the true state). Where the map errs with a Student-t tail (a local misfit
    scale, :mod:`tangraph.sensors.misfit`) the soundings' part of the variance is at the scale's
    estimate and ``nis`` is the square of a Student-t of ``dof`` degrees of freedom, ``F(1,
    dof)`` (infinite: chi-square(1)): a map that says it errs by several times its stated error
    in patches does not say the cloud is lost where it does.

    Examples
    --------
    >>> Innovation(nis=0.5, best_chi2=25.0, n_soundings=30).inconsistent(1e-3)
    False
    >>> Innovation(nis=0.5, best_chi2=400.0, n_soundings=30).inconsistent(1e-3)
    True
    >>> Innovation(nis=20.0, best_chi2=25.0, n_soundings=30).inconsistent(1e-3)
    True
    >>> Innovation(nis=20.0, best_chi2=25.0, n_soundings=30, dof=3.0).inconsistent(1e-3)
    False
    """

    nis: float
    best_chi2: float
    n_soundings: int
    dof: float = float("inf")

    def nis_beyond(self, alpha: float) -> bool:
        """Whether ``nis`` is beyond its quantile ``1 - alpha`` (chi-square(1), or ``F(1, dof)``)."""
        return bool(self.nis > _nis_quantile(alpha, self.dof))

    def inconsistent(self, alpha: float) -> bool:
        """Whether either statistic is beyond its quantile ``1 - alpha``."""
        return self.nis_beyond(alpha) or bool(self.best_chi2 > _chi2_quantile(alpha, self.n_soundings))


@functools.lru_cache(maxsize=1024)
def _chi2_quantile(alpha: float, dof: int) -> float:
    """``chi2.isf(alpha, dof)``, cached: asked at every ping, for few distinct sounding counts."""
    return float(stats.chi2.isf(alpha, dof))


def _nis_quantile(alpha: float, dof: float) -> float:
    """The quantile ``1 - alpha`` of one squared innovation: chi-square(1), or ``F(1, dof)`` for a
    Student-t of ``dof`` degrees of freedom (its square)."""
    if not np.isfinite(dof):
        return _chi2_quantile(alpha, 1)
    return float(special.fdtri(1.0, dof, 1.0 - alpha))  # stats.f.isf, 30x faster (every ping)


@dataclasses.dataclass(frozen=True, eq=False)
class Measurement:
    """A terrain update (:func:`measure`): the weighted ``belief``, the last stage's ``update``
    (None for a ping without soundings), the ping's ``innovation``, the stages' ``exponents``
    (summing to 1) and the ESS after each stage (``stage_ess``)."""

    belief: Belief
    update: TerrainUpdate | None
    innovation: Innovation | None = None
    exponents: tuple[float, ...] = ()
    stage_ess: tuple[float, ...] = ()
    gated: bool = False

    @property
    def tempered(self) -> bool:
        return len(self.exponents) > 1


Step = Callable[..., StepResult]


def predict(belief: Belief, ping: Ping, model: FilterModel, *, rng: np.random.Generator,
            extra_std: float = 0.0) -> Belief:  # fmt: skip
    """The belief moved through the motion model (positions and calibrations), its tide
    posterior through the tide's drift."""
    assert belief.calibration is not None  # Belief.__post_init__ fills it
    particles, calibration = model.motion.predict(
        belief.particles, belief.calibration, ping, rng=rng, extra_std=extra_std
    )
    tide, tide_var, drift = predict_tide(belief.tide, belief.tide_var, belief.tide_drift, model.navigation,
                                         ping)
    return belief.replace(particles=particles, calibration=calibration, tide=tide, tide_var=tide_var,
                          tide_drift=drift)


def evaluate(belief: Belief, ping: Ping, model: FilterModel,
             earlier: TerrainUpdate | None = None) -> TerrainUpdate:
    """The terrain likelihood of a ping for every particle of a belief (its positions, tide
    posteriors, heading errors and weights); ``earlier``: an earlier evaluation of the same ping,
    whose information exponents and soundings' variances are reused (None: from this belief)."""
    assert belief.calibration is not None  # Belief.__post_init__ fills it
    return model.terrain.evaluate(
        belief.particles, belief.tide, belief.tide_var, ping, heading_error=belief.calibration[:, 1],
        weights=belief.weights, earlier=earlier, scale=belief.misfit,
    )


def innovation(
    belief: Belief, update: TerrainUpdate | PingLikelihood, ping: Ping, model: FilterModel
) -> Innovation | None:
    """The :class:`Innovation` of a ping for the predicted ``belief`` (weights before the ping)
    and its terrain ``update``; None when no particle of positive weight can explain it."""
    finite = np.isfinite(update.log_likelihood) & np.isfinite(update.predicted)
    finite &= belief.log_weights > -np.inf
    if ping.n_soundings == 0 or not finite.any():
        return None
    w = belief.weights[finite]
    w = w / w.sum()
    predicted = update.predicted[finite]
    mean = w @ predicted
    spread = w @ (predicted - mean) ** 2
    b = ping.n_soundings
    noise = model.terrain.sounding_std**2 / b
    if ping.variance is not None:  # white noise averages out over the ping, its map error may not
        noise = model.navigation.sounding_std**2 / b + float(np.mean(cast(np.ndarray, ping.map_variance)))
    scale = getattr(update, "scale", None)  # the local misfit scale the ping was weighed with
    dof = float("inf")
    if scale is not None:  # the soundings err at its estimate, with its Student-t tail
        noise, dof = noise * max(scale.factor, 1.0), 2.0 * scale.shape
    variance = spread + noise + belief.tide_var
    nis = float((np.mean(ping.depths) - mean) ** 2 / variance)
    best = float(-2.0 * np.max(update.log_likelihood[finite]))
    return Innovation(nis, best, b, dof)


def reweight(belief: Belief, log_factor: np.ndarray, *, where: str) -> Belief:
    """The belief with its weights multiplied by ``exp(log_factor)`` and renormalised.

    Raises
    ------
    OffMap
        Every factor is zero because no particle has the map under the ping (``-inf`` is the
        likelihood of a particle with a sounding off the map).
    FilterDivergence
        Every new weight is zero.
    """
    if np.all(np.isneginf(log_factor)):
        raise OffMap(f"{where}: no particle has the map under every sounding (off the map)")
    logw = belief.log_weights + log_factor
    _, log_total = log_normalise(logw, where=where)
    return belief.replace(log_weights=logw - log_total)


def _exponent(
    log_weights: np.ndarray, log_likelihood: np.ndarray, remaining: float, fraction: float
) -> float:
    """The largest exponent ``phi <= remaining`` whose reweighting keeps the ESS at or above
    ``fraction`` times the ESS of the particles that can explain the ping (bisection)."""
    finite = np.isfinite(log_likelihood) & (log_weights > -np.inf)
    if not finite.any():
        return remaining  # nobody explains the ping: the update will say so
    lw, ll = log_weights[finite], log_likelihood[finite]

    def ess(phi: float) -> float:
        x = lw + phi * ll
        w = np.exp(x - x.max())
        return float(w.sum() ** 2 / np.sum(w * w))

    target = fraction * ess(0.0)
    if ess(remaining) >= target:
        return remaining
    low, high = 0.0, remaining
    for _ in range(50):
        mid = 0.5 * (low + high)
        if ess(mid) >= target:
            low = mid
        else:
            high = mid
    return low if low > 0 else high


def measure(
    belief: Belief,
    ping: Ping,
    model: FilterModel,
    config: ParticleConfig | None = None,
    *,
    rng: np.random.Generator | None = None,
    update: TerrainUpdate | None = None,
) -> Measurement:
    """The terrain update of a ping (weights and tide posterior), tempered when ``config`` asks
    and the likelihood is too peaked for the cloud (see the module docstring): stage ``j``
    multiplies the weights by ``p(z | x)^phi_j``, ``phi_j`` the largest exponent that keeps the
    ESS at or above ``tempering_ess`` times that of the cloud before it; between stages the
    cloud is resampled (``config.resampler``) and moved by :func:`shrink_state`. A ping without
    soundings changes nothing. ``update`` is the ping's update at ``belief`` if already computed.
    ``config`` None, its ``tempering`` False or ``rng`` None: one stage.

    Raises
    ------
    FilterDivergence
        No particle can explain the ping.
    """
    if ping.n_soundings == 0:
        return Measurement(belief, None)
    update = evaluate(belief, ping, model) if update is None else update
    first = innovation(belief, update, ping, model)
    if gated(first, config):
        return Measurement(belief, None, first, gated=True)
    tempering = config is not None and config.tempering and rng is not None
    current, remaining = belief, 1.0
    exponents: list[float] = []
    stage_ess: list[float] = []
    while True:
        last = not tempering or len(exponents) + 1 >= config.max_stages  # type: ignore[union-attr]
        phi = remaining if last else _exponent(
            current.log_weights, update.log_likelihood, remaining, config.tempering_ess  # type: ignore[union-attr]
        )  # fmt: skip
        weighted = reweight(current, phi * update.log_likelihood, where=f"ping {ping.index}")
        exponents.append(phi)
        stage_ess.append(effective_sample_size(weighted.weights))
        if phi >= remaining:
            break
        remaining -= phi
        moments = state_moments(weighted)
        resampled, _ = resample_belief(weighted, config.resampler, rng=rng)  # type: ignore[union-attr,arg-type]
        floor = np.concatenate([[1e-6, 1e-6], _kernel_floor(model, config)])  # type: ignore[arg-type]
        current = shrink_state(resampled, moments, config.kernel_bandwidth, floor, rng=rng)  # type: ignore[union-attr,arg-type]
        update = evaluate(current, ping, model, earlier=update)
    new = weighted.tide_updated(update).replace(misfit=update.scale_after(weighted.weights))
    return Measurement(new, update, first, tuple(exponents), tuple(stage_ess))


def gated(check: Innovation | None, config: ParticleConfig | None) -> bool:
    """Whether a ping whose :class:`Innovation` is ``check`` is refused by the gate
    (``config.health.ping_gate``: inconsistent at ``config.health.lost_alpha``)."""
    return bool(config is not None and config.health.ping_gate and check is not None
                and check.inconsistent(config.health.lost_alpha))


def resample_belief(
    belief: Belief, scheme: Resampler, *, rng: np.random.Generator
) -> tuple[Belief, np.ndarray]:
    """Resampled belief (equal weights) and the indices of the particles kept."""
    index = resample(belief.weights, scheme, rng=rng)
    return belief.take(index), index


def resample_if_needed(
    belief: Belief, config: ParticleConfig, *, rng: np.random.Generator, model: FilterModel | None = None
) -> tuple[Belief, np.ndarray | None, float]:
    """Resample when ESS < ``ess_threshold * N``; returns the belief, the indices kept (None if
    it did not resample) and the ESS before. With a ``model``, the resampled calibrations are
    moved by :func:`shrink_calibration` at :func:`kernel_bandwidth`."""
    ess = effective_sample_size(belief.weights)
    if ess < config.ess_threshold * belief.n_particles:
        bandwidth = kernel_bandwidth(config, ess, belief.n_particles) if model is not None else 0.0
        moments = state_moments(belief) if bandwidth > 0 else None
        new, index = resample_belief(belief, config.resampler, rng=rng)
        if bandwidth > 0:
            new = shrink_calibration(
                new, moments, bandwidth, _kernel_floor(model, config), rng=rng  # type: ignore[arg-type]
            )
        return new, index, ess
    return belief, None, ess


def kernel_bandwidth(config: ParticleConfig, ess: float, n: int) -> float:
    """The calibration kernel's ``h`` after a resampling of ``n`` particles whose ESS was
    ``ess``: ``config.kernel_bandwidth`` when the weights held at least as much as a cloud of
    ESS ``kernel_ess * n``, else its variance ``h^2`` scaled by their squared coefficient of
    variation ``n / ess - 1`` over that cloud's ``1 / kernel_ess - 1`` (the variance the kernel
    adds is in proportion to what the weights told, whatever the resampling schedule: a
    filter that resamples at every ping adds it in small steps that sum to a PF's).

    >>> from tangraph.filters import PFConfig
    >>> kernel_bandwidth(PFConfig(), 400.0, 1000), kernel_bandwidth(PFConfig(), 1000.0, 1000)
    (0.3, 0.0)
    >>> round(kernel_bandwidth(PFConfig(), 1000 / 1.25, 1000) ** 2, 4)  # a quarter of the variance
    0.0225
    """
    excess = n / max(ess, 1e-300) - 1.0
    full = 1.0 / config.kernel_ess - 1.0
    if full <= 0.0:  # kernel_ess = 1: full at every resampling
        return config.kernel_bandwidth
    return config.kernel_bandwidth * float(np.sqrt(min(max(excess, 0.0) / full, 1.0)))


def jitter(belief: Belief, std: float, *, rng: np.random.Generator) -> Belief:
    """Every particle moved by independent ``N(0, std^2 I)``."""
    if std <= 0:
        return belief
    return belief.replace(particles=belief.particles + std * rng.standard_normal(belief.particles.shape))


def _sqrtm(cov: np.ndarray) -> np.ndarray:
    """A square root ``L`` (``L L^T = cov``) of a symmetric positive semi-definite matrix."""
    values, vectors = np.linalg.eigh(0.5 * (cov + cov.T))
    return vectors * np.sqrt(np.maximum(values, 0.0))


def shrink_calibration(
    belief: Belief,
    moments: tuple[np.ndarray, np.ndarray],
    bandwidth: float,
    floor: np.ndarray,
    *,
    rng: np.random.Generator,
) -> Belief:
    """The belief with every particle's calibration ``c = (k, b)`` moved by a Liu-West shrinkage
    kernel conditional on its position: ``c' = a c + (1 - a) m(x) + h L e``, ``h = bandwidth``,
    ``a = sqrt(1 - h^2)``, ``m(x)`` the linear regression of ``c`` on the position and ``L L^T``
    the residual covariance (plus ``diag(floor^2)``), both from ``moments``
    (:func:`state_moments`, of the weighted cloud before resampling), ``e`` standard normal
    (``N x 2`` draws). A Gaussian cloud keeps its mean and covariance (positions untouched).
    """
    if bandwidth <= 0:
        return belief
    mean, cov = moments
    cxx, ccx, ccc = cov[:2, :2], cov[2:, :2], cov[2:, 2:]
    gain = ccx @ np.linalg.pinv(cxx)
    centre = mean[2:] + (belief.particles - mean[:2]) @ gain.T
    residual = ccc - gain @ ccx.T + np.diag(np.square(floor))
    assert belief.calibration is not None  # Belief.__post_init__ fills it
    a = np.sqrt(1.0 - bandwidth**2)
    noise = rng.standard_normal(belief.calibration.shape) @ _sqrtm(residual).T
    return belief.replace(calibration=a * belief.calibration + (1.0 - a) * centre + bandwidth * noise)


def shrink_state(
    belief: Belief,
    moments: tuple[np.ndarray, np.ndarray],
    bandwidth: float,
    floor: np.ndarray,
    *,
    rng: np.random.Generator,
) -> Belief:
    """The belief with every particle's full state ``s = (north, east, k, b)`` moved by a Liu-West
    shrinkage kernel: ``s' = a s + (1 - a) m + h L e`` (``m``, ``L L^T`` the weighted mean and
    covariance of ``moments``, plus ``diag(floor^2)``; ``floor (4,)``); used between tempering
    stages, where nothing else moves the particles."""
    if bandwidth <= 0:
        return belief
    mean, cov = moments
    assert belief.calibration is not None  # Belief.__post_init__ fills it
    state = np.column_stack([belief.particles, belief.calibration])
    a = np.sqrt(1.0 - bandwidth**2)
    noise = rng.standard_normal(state.shape) @ _sqrtm(cov + np.diag(np.square(floor))).T
    moved = a * state + (1.0 - a) * mean + bandwidth * noise
    return belief.replace(particles=moved[:, :2], calibration=moved[:, 2:])


def _kernel_floor(model: FilterModel, config: ParticleConfig) -> np.ndarray:
    return config.kernel_floor * model.navigation.calibration_std
