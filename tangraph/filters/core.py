"""What every particle filter shares: its configuration, the belief, the loop pieces, the runner.

A filter is a pure step ``step(belief, ping, model, config, *, rng) -> StepResult`` (it returns a
new :class:`Belief` and never writes into its inputs: a belief's arrays are read-only) plus a
call of :func:`run_particle_filter`, which loops over the pings, records the weighted mean and
covariance, the effective sample size and the resampling count, and recovers from divergence:
when every particle has zero likelihood (all off the map, or a ping no particle explains) the
step raises :class:`~tangraph.filters.FilterDivergence`; the runner logs it, draws a
fresh cloud around the dead-reckoned position of that ping with a wider spread
(``reinit_std``, times ``reinit_growth`` for each further consecutive divergence, capped at
the larger of the map's diagonal and the first re-initialisation spread), weights it by
the ping if any particle can explain it, and goes on. ``meta["n_divergences"]`` and
``meta["divergence_steps"]`` record it.
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time
from collections.abc import Callable
from typing import Any

import numba
import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.config import ParticleConfig, check_count, check_number, survey_sounding_std
from tangraph.filters.likelihood import FilterDivergence, effective_sample_size, log_normalise
from tangraph.filters.model import MotionModel, Ping, TerrainModel, TerrainUpdate, survey_pings
from tangraph.filters.resampling import Resampler, resample
from tangraph.maps.grid import BathymetryMap
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = [
    "Belief",
    "FilterModel",
    "StepResult",
    "check_run_inputs",
    "initial_belief",
    "jitter",
    "measure",
    "resample_belief",
    "resample_if_needed",
    "reweight",
    "rng_seed",
    "run_particle_filter",
    "weighted_moments",
]

_log = logging.getLogger(__name__)


@dataclasses.dataclass(frozen=True, eq=False)
class FilterModel:
    """The state-space model of a run: motion and terrain measurement."""

    motion: MotionModel
    terrain: TerrainModel

    @classmethod
    def from_config(
        cls, config: ParticleConfig, bathymetry: BathymetryMap, survey: Survey | None = None
    ) -> FilterModel:
        """The model of a config; a ``sounding_std`` of None is resolved from ``survey``."""
        sigma = config.sounding_std if config.sounding_std is not None else survey_sounding_std(survey)
        return cls(
            MotionModel(config.process_std, config.process_fraction),
            TerrainModel(bathymetry, sigma, config.tide_std),
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
    of which the last ``n_history`` are filled; ``n_fixes`` batch fixes absorbed (TERCOM-PF).
    """

    particles: np.ndarray
    log_weights: np.ndarray
    tide: np.ndarray
    tide_var: float
    history: np.ndarray
    measured: np.ndarray
    n_history: int = 0
    n_fixes: int = 0

    def __post_init__(self) -> None:
        for name in ("particles", "log_weights", "tide", "history", "measured"):
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
    whether it resampled, counts summed into the track's metadata, fix records (TERCOM-PF) and
    ``info`` for inspection (not recorded)."""

    belief: Belief
    mean: np.ndarray
    covariance: np.ndarray
    ess: float
    resampled: bool = False
    counts: dict[str, int] = dataclasses.field(default_factory=dict)
    fixes: tuple[dict[str, Any], ...] = ()
    info: dict[str, Any] = dataclasses.field(default_factory=dict)


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
) -> Belief:
    """``n`` equally weighted particles drawn from ``N(centre, std^2 I)``; ``centre`` is a
    position ``(north, east)``, shape ``(2,)`` (not a pose).

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
    return Belief(
        particles=centre + spread * rng.standard_normal((n, 2)),
        log_weights=np.full(n, -np.log(n)),
        tide=np.full(n, float(tide)),
        tide_var=float(tide_var),
        history=np.full((n, history_length), np.nan),
        measured=np.full(history_length, np.nan),
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


def reweight(belief: Belief, log_factor: np.ndarray, *, where: str) -> Belief:
    """The belief with its weights multiplied by ``exp(log_factor)`` and renormalised.

    Raises
    ------
    FilterDivergence
        Every new weight is zero.
    """
    logw = belief.log_weights + log_factor
    _, log_total = log_normalise(logw, where=where)
    return belief.replace(log_weights=logw - log_total)


def measure(belief: Belief, ping: Ping, model: FilterModel) -> tuple[Belief, TerrainUpdate | None]:
    """The terrain update of a ping (weights and tide posterior); a ping without soundings
    changes nothing (``None`` update)."""
    if ping.n_soundings == 0:
        return belief, None
    update = model.terrain.evaluate(belief.particles, belief.tide, belief.tide_var, ping)
    new = reweight(belief, update.log_likelihood, where=f"ping {ping.index}")
    return new.replace(tide=update.tide, tide_var=update.tide_var), update


def resample_belief(
    belief: Belief, scheme: Resampler, *, rng: np.random.Generator
) -> tuple[Belief, np.ndarray]:
    """Resampled belief (equal weights) and the indices of the particles kept."""
    index = resample(belief.weights, scheme, rng=rng)
    return belief.take(index), index


def resample_if_needed(
    belief: Belief, config: ParticleConfig, *, rng: np.random.Generator
) -> tuple[Belief, np.ndarray | None, float]:
    """Resample when ESS < ``ess_threshold * N``; returns the belief, the indices kept (None if
    it did not resample) and the ESS before."""
    ess = effective_sample_size(belief.weights)
    if ess < config.ess_threshold * belief.n_particles:
        new, index = resample_belief(belief, config.resampler, rng=rng)
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
) -> StepResult:
    fresh = initial_belief(
        survey.dr_pose[ping.index, :2],
        spread,
        config.n_particles,
        rng=rng,
        tide=config.tide,
        tide_var=config.tide_std**2,
        history_length=history_length,
    )
    try:
        fresh, _ = measure(fresh, ping, model)
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
    progress: bool = False,
    history_length: int = 0,
    count_keys: tuple[str, ...] = (),
) -> Track:
    """Run ``step`` over every ping of a survey and return the weighted-mean track.

    The track's heading is the dead-reckoned one (its variance NaN). ``meta`` holds ``ess``
    (per step: of the weights the step's estimate is taken from), ``n_resampled``,
    ``n_divergences``, ``divergence_steps``, ``n_particles``, ``config``, ``seed`` (the seed of
    ``rng`` at the start, :func:`rng_seed`: ``{"entropy", "spawn_key"}``, or None when it has no
    :class:`numpy.random.SeedSequence`) and the step's counts; ``timings`` ``total``, ``per_step``
    (mean), ``per_step_p99`` and ``per_step_max`` (seconds).

    Raises
    ------
    TangraphError
        ``survey``, ``bathymetry`` or ``rng`` of the wrong type.
    """
    from tqdm.auto import tqdm

    check_run_inputs(survey, bathymetry, rng, where=method)
    seed = rng_seed(rng)

    model = FilterModel.from_config(config, bathymetry, survey)
    pings = survey_pings(survey)
    k_total = survey.n_pings
    belief = initial_belief(
        survey.dr_pose[0, :2],
        config.init_std,
        config.n_particles,
        rng=rng,
        tide=config.tide,
        tide_var=config.tide_std**2,
        history_length=history_length,
    )
    mean = np.empty((k_total, 2))
    cov = np.full((k_total, 3, 3), np.nan)
    ess = np.empty(k_total)
    seconds = np.empty(k_total)
    counts: dict[str, int] = dict.fromkeys(count_keys, 0)
    fixes: list[dict[str, Any]] = []
    divergence_steps: list[int] = []
    n_resampled = consecutive = 0
    n_min, n_max, e_min, e_max = bathymetry.extent
    largest = max(float(np.hypot(n_max - n_min, e_max - e_min)), config.reinit_spread)  # cap on the spread
    started = _time.perf_counter()
    for k in tqdm(range(k_total), disable=not progress, desc=method, unit="ping", leave=False):
        t0 = _time.perf_counter()
        try:
            result = step(belief, pings[k], model, config, rng=rng)
            consecutive = 0
        except FilterDivergence as exc:
            consecutive += 1
            spread = min(config.reinit_spread * config.reinit_growth ** (consecutive - 1), largest)
            divergence_steps.append(k)
            _log.warning("%s: %s; re-initialised around dead reckoning, spread %.1f m", method, exc, spread)
            result = _recover(survey, pings[k], model, config, spread, history_length, rng)
        belief = result.belief
        mean[k], cov[k, :2, :2], ess[k] = result.mean, result.covariance, result.ess
        n_resampled += bool(result.resampled)
        for key, value in result.counts.items():
            counts[key] = counts.get(key, 0) + int(value)
        fixes.extend(result.fixes)
        seconds[k] = _time.perf_counter() - t0
    elapsed = _time.perf_counter() - started
    meta: dict[str, Any] = {
        "ess": ess.tolist(),
        "n_resampled": n_resampled,
        "n_divergences": len(divergence_steps),
        "divergence_steps": divergence_steps,
        "n_particles": config.n_particles,
        "sounding_std": model.terrain.sounding_std,
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
