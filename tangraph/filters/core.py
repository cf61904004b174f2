"""What every particle filter shares: the model, the belief, the loop pieces, the runner.

A filter is a pure step ``step(belief, ping, model, config, *, rng) -> StepResult`` (it returns a
new :class:`Belief` and never writes into its inputs: a belief's arrays are read-only) plus a
call of :func:`run_particle_filter`, which loops over the pings, records the weighted mean and
covariance, the effective sample size and the resampling count, and the calibration estimate at
the last ping (``meta["calibration"]``).

The model of the run is a :class:`~tangraph.sensors.NavigationModel` (None:
``NavigationModel.from_survey(survey)``), turned into a :class:`FilterModel` (motion and terrain
likelihood, :mod:`tangraph.filters.model`). Each particle carries its position, the constant DR
errors ``(k, b)`` (drawn from the model's priors at the start) and its tide posterior.

Honest covariances. The terrain update :func:`measure` tempers a ping whose likelihood is far
narrower than the cloud (progressive correction: exponents summing to 1, each the largest that
keeps the ESS at or above ``tempering_ess`` times the ESS before it; resampling and the shrinkage
kernel between stages), and the sounding variance it uses includes the map error. After every
resampling the calibration ``(k, b)`` is moved by a Liu-West shrinkage kernel conditional on the
position (:func:`shrink_calibration`), which keeps the cloud's mean and covariance but lets the
constant errors take new values (they have no process noise, ``b`` at most its walk).

Lost and diverged. Every ping with soundings gives an :class:`Innovation`: the normalised
innovation of its mean sounding against the weighted cloud's predictive spread (chi-square(1))
and the best particle's ``-2 log p`` (chi-square(B) at the true state). A ping where either is
beyond its ``1 - lost_alpha`` quantile is inconsistent; ``lost_pings`` consecutive inconsistent
pings (with soundings) make a ping *lost*: ``meta["n_lost"]`` and ``meta["lost_steps"]``. When
every particle has zero likelihood (all off the map, or a ping no particle explains) the step
raises :class:`~tangraph.filters.FilterDivergence`; the runner logs it, draws a fresh cloud around
the dead-reckoned position of that ping with a wider spread (``reinit_std``, times
``reinit_growth`` for each further consecutive divergence, capped at the larger of the map's
diagonal and the first re-initialisation spread), weights it by the ping if any particle can
explain it, and goes on. ``meta["n_divergences"]`` and ``meta["divergence_steps"]`` record it.
A ping under which no particle has the map (the vehicle off the map: every particle has a
sounding without a map depth) is no evidence at all: the step is the prediction alone (the
cloud moves with the dead reckoning and its covariance grows by the DR model's), recorded in
``meta["n_off_map"]`` and ``meta["off_map_steps"]``, and never a divergence. An inconsistent ping
(soundings no particle explains: a block of bad pings, or a cloud that has lost the vehicle)
does not weigh the cloud with ``ParticleConfig.ping_gate`` (off by default); a run of them is
flagged lost, and
after ``gate_pings`` of them the cloud is taken to be the wrong one and drawn afresh around its
mean with the first re-initialisation spread (``meta["n_redraws"]``, ``meta["redraw_steps"]``).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import time as _time
from collections.abc import Callable
from typing import Any

import numba
import numpy as np
from scipy import stats

from tangraph.errors import TangraphError
from tangraph.filters.config import ParticleConfig, check_count, check_number
from tangraph.filters.likelihood import FilterDivergence, OffMap, effective_sample_size, log_normalise
from tangraph.filters.model import MotionModel, Ping, TerrainModel, TerrainUpdate, survey_pings
from tangraph.filters.resampling import Resampler, resample
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel, survey_navigation_model
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = [
    "Belief",
    "FilterModel",
    "Innovation",
    "Measurement",
    "StepResult",
    "calibration_estimate",
    "check_run_inputs",
    "evaluate",
    "gated",
    "initial_belief",
    "innovation",
    "jitter",
    "measure",
    "model_belief",
    "predict",
    "resample_belief",
    "resample_if_needed",
    "reweight",
    "rng_seed",
    "run_particle_filter",
    "shrink_calibration",
    "shrink_state",
    "state_moments",
    "weighted_moments",
]

_log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, eq=False)
class FilterModel:
    """The state-space model of a run (apart from the algorithm): motion, terrain measurement and
    the navigation model they come from (start uncertainty, calibration and tide priors)."""

    motion: MotionModel
    terrain: TerrainModel
    navigation: NavigationModel = dataclasses.field(default_factory=NavigationModel)

    @classmethod
    def from_model(
        cls, navigation: NavigationModel, bathymetry: BathymetryMap, config: ParticleConfig | None = None
    ) -> FilterModel:
        """The filter model of a navigation model on a map; ``config`` adds its
        ``process_floor`` (if any) to the motion noise.

        Examples
        --------
        >>> from tangraph.maps import fractal
        >>> chart = fractal((20, 20), 5.0, rng=np.random.default_rng(0))
        >>> model = FilterModel.from_model(NavigationModel(sounding_std=0.3, map_std=0.4), chart)
        >>> round(model.terrain.sounding_std, 6)  # the map error inflates the likelihood
        0.5
        """
        if not isinstance(navigation, NavigationModel):
            raise TangraphError(
                f"model must be a tangraph.sensors.NavigationModel, got {type(navigation).__name__}"
            )
        floor = getattr(config, "process_floor", 0.0) if config is not None else 0.0
        return cls(
            MotionModel.from_model(navigation, floor),
            TerrainModel(bathymetry, navigation.measurement_std, navigation.tide_std),
            navigation,
        )


def _frozen(a, dtype=np.float64) -> np.ndarray:
    a = np.asarray(a, dtype=dtype)
    if a.flags.writeable:
        a = a.view()
        a.setflags(write=False)
    return a


@dataclasses.dataclass(frozen=True, eq=False)
class Belief:
    """A weighted particle cloud (read-only arrays).

    ``particles (N, 2)`` positions; ``log_weights (N,)`` normalised log weights; ``tide (N,)``
    and ``tide_var`` the per-particle tide posterior; ``history (N, L)`` the last ``L`` predicted
    depths of each particle and ``measured (L,)`` the measured ones (SJCPF; ``L = 0`` otherwise),
    of which the last ``n_history`` are filled; ``n_fixes`` batch fixes absorbed (TERCOM-PF);
    ``calibration (N, 2)`` each particle's constant DR errors ``(k, b)`` (speed scale, heading
    error in rad, DR minus true; None: zeros).
    """

    particles: np.ndarray
    log_weights: np.ndarray
    tide: np.ndarray
    tide_var: float
    history: np.ndarray
    measured: np.ndarray
    n_history: int = 0
    n_fixes: int = 0
    calibration: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.calibration is None:
            object.__setattr__(self, "calibration", np.zeros((np.shape(self.particles)[0], 2)))
        for name in ("particles", "log_weights", "tide", "history", "measured", "calibration"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        particles, history = self.particles, self.history
        if particles.ndim != 2 or particles.shape[1] != 2:
            raise TangraphError(f"Belief: particles must have shape (N, 2), got {particles.shape}")
        n = particles.shape[0]
        if n < 1:
            raise TangraphError("Belief: particles must hold at least one particle, got shape (0, 2)")
        for name in ("log_weights", "tide"):
            shape = getattr(self, name).shape
            if shape != (n,):
                raise TangraphError(f"Belief: {name} must have shape ({n},) as particles, got {shape}")
        if history.ndim != 2 or history.shape[0] != n:
            raise TangraphError(f"Belief: history must have shape ({n}, L) as particles, got {history.shape}")
        if self.calibration.shape != (n, 2):
            raise TangraphError(
                f"Belief: calibration must have shape ({n}, 2) as particles, got {self.calibration.shape}"
            )
        length = history.shape[1]
        if self.measured.shape != (length,):
            raise TangraphError(
                f"Belief: measured must have shape ({length},) as history's (N, L), got {self.measured.shape}"
            )
        check_number(self, "tide_var")
        check_count(self, "n_history", low=0)
        if self.n_history > length:
            raise TangraphError(f"Belief: n_history must be <= L = {length}, got {self.n_history!r}")
        check_count(self, "n_fixes", low=0)

    @property
    def n_particles(self) -> int:
        return int(self.particles.shape[0])

    @property
    def weights(self) -> np.ndarray:
        """Normalised weights ``(N,)``."""
        return np.exp(self.log_weights)

    def take(self, index: np.ndarray) -> Belief:
        """The particles ``index`` (with their tides and histories), equally weighted."""
        n = index.size
        return self.replace(
            particles=self.particles[index],
            log_weights=np.full(n, -np.log(n)),
            tide=self.tide[index],
            history=self.history[index] if self.history.shape[1] else np.empty((n, 0)),
            calibration=self.calibration[index],
        )

    def replace(self, **changes) -> Belief:
        """A copy with some fields changed (new arrays are made read-only; no other checks, as
        this runs several times per step)."""
        new = object.__new__(Belief)
        fields = dict(self.__dict__)
        for name, value in changes.items():
            if name not in fields:
                raise TypeError(f"Belief has no field {name!r}")
            fields[name] = _frozen(value) if isinstance(value, np.ndarray) else value
        new.__dict__.update(fields)
        return new


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
    fixes: tuple[dict[str, Any], ...] = ()
    info: dict[str, Any] = dataclasses.field(default_factory=dict)
    innovation: Innovation | None = None


@dataclasses.dataclass(frozen=True)
class Innovation:
    """How well the predicted cloud explains a ping of ``n_soundings`` soundings: ``nis``, the
    squared innovation of the mean sounding over its predictive variance (the weighted cloud's
    spread of predicted mean depths, plus ``sigma^2 / B`` and the tide variance; chi-square(1)
    when the model holds), and ``best_chi2``, the smallest ``-2 log p`` over the particles
    (chi-square(B) at the true state).

    Examples
    --------
    >>> Innovation(nis=0.5, best_chi2=25.0, n_soundings=30).inconsistent(1e-3)
    False
    >>> Innovation(nis=0.5, best_chi2=400.0, n_soundings=30).inconsistent(1e-3)
    True
    """

    nis: float
    best_chi2: float
    n_soundings: int

    def inconsistent(self, alpha: float) -> bool:
        """Whether either statistic is beyond its chi-square quantile ``1 - alpha``."""
        return bool(self.nis > _chi2_quantile(alpha, 1)
                    or self.best_chi2 > _chi2_quantile(alpha, self.n_soundings))


@functools.lru_cache(maxsize=1024)
def _chi2_quantile(alpha: float, dof: int) -> float:
    """``chi2.isf(alpha, dof)``, cached: asked at every ping, for few distinct sounding counts."""
    return float(stats.chi2.isf(alpha, dof))


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


def initial_belief(
    centre,
    std: float,
    n: int,
    *,
    rng: np.random.Generator,
    tide: float = 0.0,
    tide_var: float = 0.0,
    history_length: int = 0,
    calibration=(0.0, 0.0),
    calibration_std=(0.0, 0.0),
) -> Belief:
    """``n`` equally weighted particles drawn from ``N(centre, std^2 I)``; ``centre`` is a
    position ``(north, east)``, shape ``(2,)`` (not a pose). Their constant DR errors ``(k, b)``
    are drawn from ``N(calibration, diag(calibration_std^2))`` (after the positions; no draws
    when both stds are 0).

    Raises
    ------
    TangraphError
        ``centre`` not a finite ``(2,)`` array, ``std`` negative or not finite, ``n < 1``,
        ``history_length < 0``.
    """
    try:
        centre = np.asarray(centre, dtype=np.float64)
    except (TypeError, ValueError):
        raise TangraphError(
            f"initial_belief: centre must be a (north, east) position, got {centre!r}"
        ) from None
    if centre.shape != (2,) or not np.all(np.isfinite(centre)):
        raise TangraphError(
            f"initial_belief: centre must be a finite (north, east) position of shape (2,), "
            f"got shape {centre.shape}: {centre.tolist()!r}"
        )
    try:
        spread = float(std)
    except (TypeError, ValueError):
        spread = np.nan
    if not (np.isfinite(spread) and spread >= 0):
        raise TangraphError(f"initial_belief: std must be a finite number >= 0, got {std!r}")
    for name, value, low in (("n", n, 1), ("history_length", history_length, 0)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise TangraphError(f"initial_belief: {name} must be an integer >= {low}, got {value!r}")
    particles = centre + spread * rng.standard_normal((n, 2))
    cal_mean = np.broadcast_to(np.asarray(calibration, dtype=np.float64), (2,))
    cal_std = np.broadcast_to(np.asarray(calibration_std, dtype=np.float64), (2,))
    if np.any(cal_std > 0):
        cal = cal_mean + cal_std * rng.standard_normal((n, 2))
    else:
        cal = np.tile(cal_mean, (n, 1))
    return Belief(
        particles=particles,
        log_weights=np.full(n, -np.log(n)),
        tide=np.full(n, float(tide)),
        tide_var=float(tide_var),
        history=np.full((n, history_length), np.nan),
        measured=np.full(history_length, np.nan),
        calibration=cal,
    )


def model_belief(
    centre, model: FilterModel, n: int, *, rng: np.random.Generator, std: float | None = None,
    history_length: int = 0,
) -> Belief:  # fmt: skip
    """The start cloud of a model: ``n`` particles around ``centre`` with the model's
    ``initial_position_std`` (or ``std``), tide prior and calibration priors."""
    nav = model.navigation
    return initial_belief(
        centre,
        nav.initial_position_std if std is None else std,
        n,
        rng=rng,
        tide=nav.tide,
        tide_var=nav.tide_std**2,
        history_length=history_length,
        calibration=nav.calibration_prior,
        calibration_std=nav.calibration_std,
    )


@numba.njit(cache=True, nogil=True)
def _moments(log_weights, particles):
    """Weighted mean (2,) and covariance (2, 2) of normalised log weights ``(N,)`` and particles
    ``(N, 2)`` (the caller checks the shapes: no bounds checks here)."""
    n = log_weights.size
    mean = np.zeros(2)
    for p in range(n):
        w = np.exp(log_weights[p])
        mean[0] += w * particles[p, 0]
        mean[1] += w * particles[p, 1]
    cov = np.zeros((2, 2))
    for p in range(n):
        w = np.exp(log_weights[p])
        dn = particles[p, 0] - mean[0]
        de = particles[p, 1] - mean[1]
        cov[0, 0] += w * dn * dn
        cov[0, 1] += w * dn * de
        cov[1, 1] += w * de * de
    cov[1, 0] = cov[0, 1]
    return mean, cov


def weighted_moments(belief: Belief) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean ``(2,)`` and covariance ``(2, 2)`` (second moment about the mean).

    Raises
    ------
    TangraphError
        The particles are not ``(N, 2)`` with ``N`` the number of weights (a belief made by
        :meth:`Belief.replace`, which does not check shapes).
    """
    particles, log_weights = belief.particles, belief.log_weights
    if particles.ndim != 2 or particles.shape[1] != 2 or log_weights.shape != (particles.shape[0],):
        raise TangraphError(
            f"weighted_moments: particles (N, 2) and log_weights (N,) do not match: "
            f"{particles.shape}, {log_weights.shape}"
        )
    return _moments(log_weights, particles)


def check_run_inputs(survey, bathymetry, rng, *, where: str, rng_optional: bool = False) -> None:
    """Refuse (with a :class:`~tangraph.errors.TangraphError` naming the argument) a ``survey``
    that is not a :class:`~tangraph.survey.Survey`, a ``bathymetry`` that is not a
    :class:`~tangraph.maps.grid.BathymetryMap` or an ``rng`` that is not a
    :class:`numpy.random.Generator` (None allowed if ``rng_optional``)."""
    if not isinstance(survey, Survey):
        raise TangraphError(f"{where}: survey must be a tangraph.survey.Survey, got {type(survey).__name__}")
    if not isinstance(bathymetry, BathymetryMap):
        raise TangraphError(
            f"{where}: bathymetry must be a tangraph.maps.grid.BathymetryMap, got {type(bathymetry).__name__}"
        )
    if not (isinstance(rng, np.random.Generator) or (rng_optional and rng is None)):
        raise TangraphError(
            f"{where}: rng must be a numpy.random.Generator (np.random.default_rng(seed)), got {rng!r}"
        )


def rng_seed(rng: np.random.Generator) -> dict[str, Any] | None:
    """The seed of a generator, as ``Track.meta["seed"]`` records it: ``{"entropy", "spawn_key"}``
    of its :class:`numpy.random.SeedSequence` (``np.random.default_rng(seed)`` makes one), None when
    the bit generator was seeded otherwise.

    Examples
    --------
    >>> rng_seed(np.random.default_rng(np.random.SeedSequence(7, spawn_key=(2, 3))))
    {'entropy': 7, 'spawn_key': [2, 3]}
    """
    seed_seq = getattr(rng.bit_generator, "seed_seq", None)
    if not isinstance(seed_seq, np.random.SeedSequence):
        return None
    entropy = seed_seq.entropy
    if entropy is not None and not isinstance(entropy, (int, np.integer)):
        entropy = [int(v) for v in np.asarray(entropy).ravel()]
    elif entropy is not None:
        entropy = int(entropy)
    return {"entropy": entropy, "spawn_key": [int(v) for v in seed_seq.spawn_key]}


def state_moments(belief: Belief) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean ``(4,)`` and covariance ``(4, 4)`` of the particles' full state
    ``(north, east, k, b)``."""
    z = np.column_stack([belief.particles, belief.calibration])
    w = belief.weights
    mean = w @ z
    d = z - mean
    return mean, (d * w[:, None]).T @ d


def calibration_estimate(belief: Belief) -> dict[str, float]:
    """The weighted mean and std of the particles' ``(k, b)``, as ``Track.meta["calibration"]``:
    ``speed_scale``, ``speed_scale_std``, ``heading_error`` (rad, DR minus true),
    ``heading_error_std``.

    Examples
    --------
    >>> b = initial_belief([0.0, 0.0], 1.0, 4000, rng=np.random.default_rng(0),
    ...                    calibration=(0.02, 0.05), calibration_std=(0.01, 0.0))
    >>> {k: round(v, 2) for k, v in calibration_estimate(b).items()}
    {'speed_scale': 0.02, 'speed_scale_std': 0.01, 'heading_error': 0.05, 'heading_error_std': 0.0}
    """
    w = belief.weights
    mean = w @ belief.calibration
    var = w @ (belief.calibration - mean) ** 2
    std = np.sqrt(np.maximum(var, 0.0))
    return {
        "speed_scale": float(mean[0]),
        "speed_scale_std": float(std[0]),
        "heading_error": float(mean[1]),
        "heading_error_std": float(std[1]),
    }


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
    state = np.column_stack([belief.particles, belief.calibration])
    a = np.sqrt(1.0 - bandwidth**2)
    noise = rng.standard_normal(state.shape) @ _sqrtm(cov + np.diag(np.square(floor))).T
    moved = a * state + (1.0 - a) * mean + bandwidth * noise
    return belief.replace(particles=moved[:, :2], calibration=moved[:, 2:])


def _kernel_floor(model: FilterModel, config: ParticleConfig) -> np.ndarray:
    return config.kernel_floor * model.navigation.calibration_std


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


def evaluate(belief: Belief, ping: Ping, model: FilterModel, exponent=None) -> TerrainUpdate:
    """The terrain likelihood of a ping for every particle of a belief (its positions, tide
    posteriors, heading errors and weights); ``exponent``: the information exponents of an
    earlier evaluation of the same ping (None: from this belief)."""
    return model.terrain.evaluate(
        belief.particles, belief.tide, belief.tide_var, ping, heading_error=belief.calibration[:, 1],
        weights=belief.weights, exponent=exponent,
    )


def innovation(belief: Belief, update: TerrainUpdate, ping: Ping, model: FilterModel) -> Innovation | None:
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
        noise = model.navigation.sounding_std**2 / b + float(np.mean(ping.map_variance))
    variance = spread + noise + belief.tide_var
    nis = float((np.mean(ping.depths) - mean) ** 2 / variance)
    best = float(-2.0 * np.max(update.log_likelihood[finite]))
    return Innovation(nis, best, b)


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
        update = evaluate(current, ping, model, exponent=update.exponent)
    new = weighted.replace(tide=update.tide, tide_var=update.tide_var)
    return Measurement(new, update, first, tuple(exponents), tuple(stage_ess))


def gated(check: Innovation | None, config: ParticleConfig | None) -> bool:
    """Whether a ping whose :class:`Innovation` is ``check`` is refused by ``config.ping_gate``
    (inconsistent at ``config.lost_alpha``)."""
    return bool(config is not None and getattr(config, "ping_gate", False) and check is not None
                and check.inconsistent(config.lost_alpha))


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
    moved by :func:`shrink_calibration` (``config.kernel_bandwidth``)."""
    ess = effective_sample_size(belief.weights)
    if ess < config.ess_threshold * belief.n_particles:
        moments = state_moments(belief) if model is not None else None
        new, index = resample_belief(belief, config.resampler, rng=rng)
        if model is not None:
            new = shrink_calibration(
                new, moments, config.kernel_bandwidth, _kernel_floor(model, config), rng=rng  # type: ignore[arg-type]
            )
        return new, index, ess
    return belief, None, ess


def jitter(belief: Belief, std: float, *, rng: np.random.Generator) -> Belief:
    """Every particle moved by independent ``N(0, std^2 I)``."""
    if std <= 0:
        return belief
    return belief.replace(particles=belief.particles + std * rng.standard_normal(belief.particles.shape))


def _recover(
    survey: Survey,
    ping: Ping,
    model: FilterModel,
    config: ParticleConfig,
    spread: float,
    history_length: int,
    rng: np.random.Generator,
    centre: np.ndarray | None = None,
) -> StepResult:
    """A fresh cloud of ``spread`` (m) around ``centre`` (default the ping's dead-reckoned
    position), weighed by the ping when any particle explains it."""
    centre = survey.dr_pose[ping.index, :2] if centre is None else centre
    fresh = model_belief(
        centre, model, config.n_particles, rng=rng, std=spread, history_length=history_length,
    )  # fmt: skip
    try:
        fresh = measure(fresh, ping, model).belief
    except FilterDivergence:
        pass  # nobody explains this ping either: keep the prior cloud
    mean, cov = weighted_moments(fresh)
    return StepResult(fresh, mean, cov, effective_sample_size(fresh.weights))


def run_particle_filter(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: ParticleConfig,
    step: Step,
    *,
    method: str,
    rng: np.random.Generator,
    model: NavigationModel | None = None,
    progress: bool = False,
    history_length: int = 0,
    count_keys: tuple[str, ...] = (),
) -> Track:
    """Run ``step`` over every ping of a survey and return the weighted-mean track.

    ``model`` is the run's :class:`~tangraph.sensors.NavigationModel` (None:
    ``NavigationModel.from_survey(survey)``). The track's heading is the dead-reckoned one (its
    variance NaN). ``meta`` holds ``ess`` (per step: of the weights the step's estimate is taken
    from), ``n_resampled``, ``n_divergences``, ``divergence_steps``, ``n_lost``, ``lost_steps``,
    ``n_off_map``, ``off_map_steps``, ``n_redraws``, ``redraw_steps`` (see the module
    docstring), ``n_tempered`` (pings whose
    update took more than one stage), ``n_gated`` (pings the ping gate refused,
    ``ParticleConfig.ping_gate``), ``calibration`` (:func:`calibration_estimate` at the last
    ping), ``n_particles``,
    ``sounding_std`` (the likelihood's, map error included), ``navigation_model``
    (``model.as_dict()``), ``config``, ``seed`` (the seed of ``rng`` at the start,
    :func:`rng_seed`: ``{"entropy", "spawn_key"}``, or None when it has no
    :class:`numpy.random.SeedSequence`) and the step's counts; ``timings`` ``total``,
    ``per_step`` (mean), ``per_step_p99`` and ``per_step_max`` (seconds).

    Raises
    ------
    TangraphError
        ``survey``, ``bathymetry``, ``rng`` or ``model`` of the wrong type, or no ``model`` for
        a survey that records no DR model.
    """
    from tqdm.auto import tqdm

    check_run_inputs(survey, bathymetry, rng, where=method)
    seed = rng_seed(rng)
    navigation = survey_navigation_model(survey, model, where=method)
    filter_model = FilterModel.from_model(navigation, bathymetry, config)
    pings = survey_pings(survey, bathymetry, navigation)
    k_total = survey.n_pings
    belief = model_belief(
        survey.dr_pose[0, :2], filter_model, config.n_particles, rng=rng, history_length=history_length
    )
    mean = np.empty((k_total, 2))
    cov = np.full((k_total, 3, 3), np.nan)
    ess = np.empty(k_total)
    seconds = np.empty(k_total)
    counts: dict[str, int] = dict.fromkeys(("n_tempered", "n_gated", *count_keys), 0)
    fixes: list[dict[str, Any]] = []
    divergence_steps: list[int] = []
    lost_steps: list[int] = []
    off_map_steps: list[int] = []
    n_resampled = consecutive = streak = gated_run = 0
    redraw_steps: list[int] = []
    first_spread = config.reinit_spread(navigation.initial_position_std)
    n_min, n_max, e_min, e_max = bathymetry.extent
    largest = max(float(np.hypot(n_max - n_min, e_max - e_min)), first_spread)  # cap on the spread
    started = _time.perf_counter()
    for k in tqdm(range(k_total), disable=not progress, desc=method, unit="ping", leave=False):
        t0 = _time.perf_counter()
        try:
            result = step(belief, pings[k], filter_model, config, rng=rng)
            consecutive = 0
        except OffMap:  # no information: the prediction alone, its covariance grown by the DR's
            off_map_steps.append(k)
            moved = predict(belief, pings[k], filter_model, rng=rng)
            mean_k, cov_k = weighted_moments(moved)
            result = StepResult(moved, mean_k, cov_k, effective_sample_size(moved.weights))
        except FilterDivergence as exc:
            consecutive += 1
            spread = min(first_spread * config.reinit_growth ** (consecutive - 1), largest)
            divergence_steps.append(k)
            _log.warning("%s: %s; re-initialised around dead reckoning, spread %.1f m", method, exc, spread)
            result = _recover(survey, pings[k], filter_model, config, spread, history_length, rng)
        if result.innovation is not None:
            streak = streak + 1 if result.innovation.inconsistent(config.lost_alpha) else 0
            if streak >= config.lost_pings:
                lost_steps.append(k)
            gated_run = gated_run + 1 if result.counts.get("n_gated") else 0
            if gated_run >= config.gate_pings:  # the gate's way out: the cloud is the wrong one
                redraw_steps.append(k)
                _log.info("%s: %d pings in a row gated at ping %d; cloud drawn afresh around its mean",
                          method, gated_run, k)
                result = _recover(survey, pings[k], filter_model, config, first_spread, history_length,
                                  rng, centre=result.mean)
                gated_run = 0
        belief = result.belief
        mean[k], cov[k, :2, :2], ess[k] = result.mean, result.covariance, result.ess
        n_resampled += bool(result.resampled)
        for key, value in result.counts.items():
            counts[key] = counts.get(key, 0) + int(value)
        fixes.extend(result.fixes)
        seconds[k] = _time.perf_counter() - t0
    elapsed = _time.perf_counter() - started
    if lost_steps:
        _log.warning("%s: lost at %d pings (first %d)", method, len(lost_steps), lost_steps[0])
    if off_map_steps:
        _log.warning("%s: %d pings off the map (first %d): dead reckoning only there", method,
                     len(off_map_steps), off_map_steps[0])
    meta: dict[str, Any] = {
        "ess": ess.tolist(),
        "n_resampled": n_resampled,
        "n_divergences": len(divergence_steps),
        "divergence_steps": divergence_steps,
        "n_lost": len(lost_steps),
        "lost_steps": lost_steps,
        "n_off_map": len(off_map_steps),
        "off_map_steps": off_map_steps,
        "n_redraws": len(redraw_steps),
        "redraw_steps": redraw_steps,
        "calibration": calibration_estimate(belief),
        "n_particles": config.n_particles,
        "sounding_std": filter_model.terrain.sounding_std,
        "navigation_model": navigation.as_dict(),
        "config": config.as_dict(),
        "seed": seed,
        **counts,
    }
    if fixes or count_keys:
        meta["fixes"] = fixes
    return Track(
        time=survey.time,
        pose=np.column_stack([mean, survey.dr_pose[:, 2]]),
        covariance=cov,
        method=method,
        timings=step_timings(elapsed, seconds),
        meta=meta,
    )


def step_timings(elapsed: float, seconds: np.ndarray) -> dict[str, float]:
    """``total``, ``per_step`` (mean), ``per_step_p99`` and ``per_step_max`` in seconds."""
    return {
        "total": float(elapsed),
        "per_step": float(elapsed / seconds.size),
        "per_step_p99": float(np.percentile(seconds, 99)),
        "per_step_max": float(seconds.max()),
    }


def predict(belief: Belief, ping: Ping, model: FilterModel, *, rng: np.random.Generator,
            extra_std: float = 0.0) -> Belief:  # fmt: skip
    """The belief moved through the motion model (positions and calibrations)."""
    particles, calibration = model.motion.predict(
        belief.particles, belief.calibration, ping, rng=rng, extra_std=extra_std
    )
    return belief.replace(particles=particles, calibration=calibration)
