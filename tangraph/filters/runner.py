"""The particle filters' runner: the loop over the pings, its recovery policy and its record.

:func:`run_particle_filter` runs a filter's step (:data:`~tangraph.filters.steps.Step`) over
every ping and records the weighted mean and covariance, the effective sample size and the
resampling count, and the calibration estimate at the last ping (``meta["calibration"]``).

The model of the run is a :class:`~tangraph.sensors.NavigationModel` (None:
``NavigationModel.from_survey(survey)``), turned into a
:class:`~tangraph.filters.model.FilterModel` (motion and terrain likelihood,
:mod:`tangraph.filters.model`).

Lost and diverged. Every ping with soundings gives an :class:`~tangraph.filters.steps.Innovation`:
the normalised innovation of its mean sounding against the weighted cloud's predictive spread
(chi-square(1)) and the best particle's ``-2 log p`` (chi-square(B) at the true state). A ping
where either is beyond its ``1 - lost_alpha`` quantile is inconsistent; ``lost_pings``
consecutive inconsistent pings (with soundings) make a ping *lost*: ``meta["n_lost"]`` and
``meta["lost_steps"]``. When every particle has zero likelihood (all off the map, or a ping no
particle explains) the step raises :class:`~tangraph.filters.FilterDivergence`; the runner logs
it, draws a fresh cloud around the dead-reckoned position of that ping with a wider spread
(``reinit_std``, times ``reinit_growth`` for each further consecutive divergence, capped at the
larger of the map's diagonal and the first re-initialisation spread), weights it by the ping if
any particle can explain it, and goes on. ``meta["n_divergences"]`` and
``meta["divergence_steps"]`` record it. A ping under which no particle has the map (the vehicle
off the map: every particle has a sounding without a map depth) is no evidence at all: the step
is the prediction alone (the cloud moves with the dead reckoning and its covariance grows by the
DR model's), recorded in ``meta["n_off_map"]`` and ``meta["off_map_steps"]``, and never a
divergence. An inconsistent ping (soundings no particle explains: a block of bad pings, or a
cloud that has lost the vehicle) does not weigh the cloud with ``FilterHealth.ping_gate`` (off
by default); a run of them is flagged lost, and after ``gate_pings`` of them the cloud is taken
to be the wrong one and drawn afresh around its mean with the first re-initialisation spread
(``meta["n_redraws"]``, ``meta["redraw_steps"]``).
"""

from __future__ import annotations

import dataclasses
import logging
import time as _time
from typing import Any

import numpy as np

from tangraph.errors import TangraphError
from tangraph.filters.belief import Belief, calibration_estimate, model_belief, weighted_moments
from tangraph.filters.config import ParticleConfig
from tangraph.filters.likelihood import FilterDivergence, OffMap, effective_sample_size
from tangraph.filters.model import FilterModel, Ping, survey_pings
from tangraph.filters.steps import Step, StepResult, measure, predict
from tangraph.fix_records import FixRecord
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel, survey_navigation_model
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["check_run_inputs", "rng_seed", "run_particle_filter", "step_timings"]

_log = logging.getLogger(__name__)


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


def step_timings(elapsed: float, seconds: np.ndarray) -> dict[str, float]:
    """``total``, ``per_step`` (mean), ``per_step_p99`` and ``per_step_max`` in seconds."""
    return {
        "total": float(elapsed),
        "per_step": float(elapsed / seconds.size),
        "per_step_p99": float(np.percentile(seconds, 99)),
        "per_step_max": float(seconds.max()),
    }


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


@dataclasses.dataclass(eq=False)
class _Recovery:
    """The runner's recovery policy over a run (see the module docstring) and the pings it acted
    on: off the map, diverged, lost and drawn afresh."""

    survey: Survey
    model: FilterModel
    config: ParticleConfig
    history_length: int
    method: str
    first_spread: float  # the first re-initialisation's spread (m)
    largest: float  # the cap on the spread
    consecutive: int = 0  # divergences in a row
    streak: int = 0  # inconsistent pings in a row
    gated_run: int = 0  # gated pings in a row
    divergence_steps: list[int] = dataclasses.field(default_factory=list)
    lost_steps: list[int] = dataclasses.field(default_factory=list)
    off_map_steps: list[int] = dataclasses.field(default_factory=list)
    redraw_steps: list[int] = dataclasses.field(default_factory=list)

    @classmethod
    def of(cls, survey: Survey, bathymetry: BathymetryMap, model: FilterModel, config: ParticleConfig,
           history_length: int, method: str) -> _Recovery:  # fmt: skip
        first_spread = config.health.reinit_spread(model.navigation.initial_position_std)
        n_min, n_max, e_min, e_max = bathymetry.extent
        largest = max(float(np.hypot(n_max - n_min, e_max - e_min)), first_spread)  # cap on the spread
        return cls(survey, model, config, history_length, method, first_spread, largest)

    def step(self, step: Step, belief: Belief, ping: Ping, k: int, rng: np.random.Generator) -> StepResult:
        """``step`` at ping ``k``; off the map: the prediction alone; diverged: a fresh cloud around
        the dead-reckoned position, wider for every further divergence in a row."""
        try:
            result = step(belief, ping, self.model, self.config, rng=rng)
            self.consecutive = 0
        except OffMap:  # no information: the prediction alone, its covariance grown by the DR's
            self.off_map_steps.append(k)
            moved = predict(belief, ping, self.model, rng=rng)
            mean_k, cov_k = weighted_moments(moved)
            result = StepResult(moved, mean_k, cov_k, effective_sample_size(moved.weights))
        except FilterDivergence as exc:
            self.consecutive += 1
            growth = self.config.health.reinit_growth ** (self.consecutive - 1)
            spread = min(self.first_spread * growth, self.largest)
            self.divergence_steps.append(k)
            _log.warning("%s: %s; re-initialised around dead reckoning, spread %.1f m", self.method, exc,
                         spread)
            result = _recover(self.survey, ping, self.model, self.config, spread, self.history_length, rng)
        return result

    def watch(self, result: StepResult, ping: Ping, k: int, rng: np.random.Generator) -> StepResult:
        """The lost test of ping ``k``'s ``result`` and the gate's way out: after ``gate_pings``
        gated pings in a row, a cloud drawn afresh around the estimate (else ``result``)."""
        if result.innovation is None:
            return result
        config = self.config
        self.streak = self.streak + 1 if result.innovation.inconsistent(config.health.lost_alpha) else 0
        if self.streak >= config.health.lost_pings:
            self.lost_steps.append(k)
        self.gated_run = self.gated_run + 1 if result.counts.get("n_gated") else 0
        if self.gated_run >= config.health.gate_pings:  # the gate's way out: the cloud is the wrong one
            self.redraw_steps.append(k)
            _log.info("%s: %d pings in a row gated at ping %d; cloud drawn afresh around its mean",
                      self.method, self.gated_run, k)
            result = _recover(self.survey, ping, self.model, config, self.first_spread, self.history_length,
                              rng, centre=result.mean)
            self.gated_run = 0
        return result

    def warn(self) -> None:
        """Log the lost and off-map pings of the run."""
        if self.lost_steps:
            _log.warning("%s: lost at %d pings (first %d)", self.method, len(self.lost_steps),
                         self.lost_steps[0])
        if self.off_map_steps:
            _log.warning("%s: %d pings off the map (first %d): dead reckoning only there", self.method,
                         len(self.off_map_steps), self.off_map_steps[0])


class _Trace:
    """What the runner records of every ping: the estimate, the ESS and the step's time, and over
    the run the resampling count, the steps' counts and their fixes."""

    def __init__(self, n_pings: int, count_keys: tuple[str, ...]) -> None:
        self.mean = np.empty((n_pings, 2))
        self.cov = np.full((n_pings, 3, 3), np.nan)
        self.ess = np.empty(n_pings)
        self.seconds = np.empty(n_pings)
        self.counts: dict[str, int] = dict.fromkeys(("n_tempered", "n_gated", *count_keys), 0)
        self.fixes: dict[int, FixRecord] = {}  # by ping: a later step may settle a held fix's record
        self.n_resampled = 0

    def add(self, k: int, result: StepResult) -> None:
        self.mean[k], self.cov[k, :2, :2], self.ess[k] = result.mean, result.covariance, result.ess
        self.n_resampled += bool(result.resampled)
        for key, value in result.counts.items():
            self.counts[key] = self.counts.get(key, 0) + int(value)
        self.fixes.update((record.index, record) for record in result.fixes)


def _meta(trace: _Trace, recovery: _Recovery, belief: Belief, seed: dict[str, Any] | None,
          count_keys: tuple[str, ...]) -> dict[str, Any]:  # fmt: skip
    """The track's ``meta`` (see :func:`run_particle_filter`)."""
    config, model = recovery.config, recovery.model
    meta: dict[str, Any] = {
        "ess": trace.ess.tolist(),
        "n_resampled": trace.n_resampled,
        "n_divergences": len(recovery.divergence_steps),
        "divergence_steps": recovery.divergence_steps,
        "n_lost": len(recovery.lost_steps),
        "lost_steps": recovery.lost_steps,
        "n_off_map": len(recovery.off_map_steps),
        "off_map_steps": recovery.off_map_steps,
        "n_redraws": len(recovery.redraw_steps),
        "redraw_steps": recovery.redraw_steps,
        "calibration": calibration_estimate(belief),
        "n_particles": config.n_particles,
        "sounding_std": model.terrain.sounding_std,
        "navigation_model": model.navigation.as_dict(),
        "config": config.as_dict(),
        "seed": seed,
        **trace.counts,
    }
    return meta


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
    ``FilterHealth.ping_gate``), ``calibration`` (:func:`calibration_estimate` at the last
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
    navigation = survey_navigation_model(survey, model, where=method, bathymetry=bathymetry)
    filter_model = FilterModel.from_model(navigation, bathymetry, config)
    pings = survey_pings(survey, bathymetry, navigation)
    belief = model_belief(
        survey.dr_pose[0, :2], filter_model, config.n_particles, rng=rng, history_length=history_length
    )
    trace = _Trace(survey.n_pings, count_keys)
    recovery = _Recovery.of(survey, bathymetry, filter_model, config, history_length, method)
    started = _time.perf_counter()
    for k in tqdm(range(survey.n_pings), disable=not progress, desc=method, unit="ping", leave=False):
        t0 = _time.perf_counter()
        result = recovery.watch(recovery.step(step, belief, pings[k], k, rng), pings[k], k, rng)
        belief = result.belief
        trace.add(k, result)
        trace.seconds[k] = _time.perf_counter() - t0
    elapsed = _time.perf_counter() - started
    recovery.warn()
    return Track(
        time=survey.time,
        pose=np.column_stack([trace.mean, survey.dr_pose[:, 2]]),
        covariance=trace.cov,
        method=method,
        timings=step_timings(elapsed, trace.seconds),
        meta=_meta(trace, recovery, belief, seed, count_keys),
        fixes=tuple(trace.fixes.values()) if trace.fixes or count_keys else None,
    )
