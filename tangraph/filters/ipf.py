"""Han, Chen & Shen (2020): the improved particle filter with auxiliary sampling (IPF).

A bootstrap PF whose resampling keeps the particles distinct. At ping ``k`` every particle
``x_{k-1}^i`` is moved through the transition density, ``x_k^i ~ p(. | x_{k-1}^i)``, and weighted by
the ping's likelihood (Han et al. eq. 2). When the effective sample size (eq. 6) falls below
``ess_threshold * N``:

1. resample: the indices ``a_j`` drawn by the weights give each parent ``i`` its copy count
   ``N_c^i`` (recorded in ``StepResult.info``: ``parents``, ``copies``, ``ancestors``);
2. instead of copying a parent, each of its ``N_c^i`` children is re-drawn from the parent's own
   transition density, ``x_k^j ~ p(. | x_{k-1}^{a_j})`` (the parent's previous state moved by the
   dead-reckoned increment plus fresh process noise), so no two children coincide;
3. each child is weighted by the likelihood ratio to its parent, ``w_j ∝ p(y_k | x_k^j) /
   p(y_k | x_k^{a_j})`` (the second-stage weight of an auxiliary particle filter whose first-stage
   point is the parent's own prediction; the paper's step 3 is garbled, this is its reading in
   SEEDS.md), and the weights are renormalised.

At ping 0 there is no transition to redraw from (the first ping does not move the particles,
:meth:`~tangraph.filters.model.MotionModel.predict`): children would be copies of their parents with
ratio 1, so a resampling there is plain (copies, equal weights; ``info["auxiliary"]`` False), as
in the bootstrap PF: the estimate and ``ess`` are those of the weighted cloud before it. The copies
separate at the next ping's prediction.

Otherwise the estimate is the weighted mean and second moment of the cloud the step returns, and
the step's ``ess`` is that cloud's (after the children's re-weighting: the weights the estimate's
Monte Carlo error depends on). If no child can be weighted (every child off the map) the step
falls back to plain copies.

The children's calibrations ``(k, b)`` are their parents' moved by the shrinkage kernel
(:func:`~tangraph.filters.steps.shrink_calibration`) before they are redrawn. A ping whose
likelihood is too peaked for the cloud (the ESS after it below ``tempering_ess`` times the ESS
before, ``tempering`` on) is a tempered bootstrap update instead (:func:`~tangraph.filters.steps.measure`,
then resampling if needed as the bootstrap PF; ``info["tempered"]`` True): the auxiliary redraw
has no single transition to redraw from once the cloud has been moved between stages.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.filters.belief import Belief, state_moments, weighted_moments
from tangraph.filters.config import ParticleConfig
from tangraph.filters.likelihood import FilterDivergence, effective_sample_size
from tangraph.filters.model import FilterModel, Ping
from tangraph.filters.resampling import resample
from tangraph.filters.runner import run_particle_filter
from tangraph.filters.steps import (
    StepResult,
    _kernel_floor,
    evaluate,
    gated,
    innovation,
    kernel_bandwidth,
    measure,
    predict,
    resample_if_needed,
    reweight,
    shrink_calibration,
)
from tangraph.maps.grid import BathymetryMap
from tangraph.sensors import NavigationModel
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["IPFConfig", "ipf", "ipf_step"]


@dataclasses.dataclass(frozen=True)
class IPFConfig(ParticleConfig):
    """Settings of the IPF: those of :class:`~tangraph.filters.ParticleConfig`, with Han et
    al.'s replay particle count (2000) as default."""

    n_particles: int = 2000


def _tempered(
    belief: Belief, ping: Ping, model: FilterModel, config: ParticleConfig, update, rng
) -> StepResult:
    measured = measure(belief, ping, model, config, rng=rng, update=update)
    mean, cov = weighted_moments(measured.belief)
    new, index, ess = resample_if_needed(measured.belief, config, rng=rng, model=model)
    info = {"tempered": True, "auxiliary": False, "exponents": measured.exponents}
    return StepResult(
        new, mean, cov, ess, resampled=index is not None, counts={"n_tempered": 1}, info=info,
        innovation=measured.innovation,
    )  # fmt: skip


def _needs_tempering(belief: Belief, weighted: Belief, update, config: ParticleConfig) -> bool:
    if not config.tempering:
        return False
    finite = np.isfinite(update.log_likelihood)
    before = belief.weights[finite]
    if before.sum() <= 0:
        return False
    before = before / before.sum()
    return effective_sample_size(weighted.weights) < config.tempering_ess * effective_sample_size(before)


def ipf_step(
    belief: Belief, ping: Ping, model: FilterModel, config: ParticleConfig, *, rng: np.random.Generator
) -> StepResult:
    """One IPF step (see the module docstring)."""
    moved = predict(belief, ping, model, rng=rng)
    if ping.n_soundings == 0:
        mean, cov = weighted_moments(moved)
        return StepResult(moved, mean, cov, effective_sample_size(moved.weights))
    update = evaluate(moved, ping, model)
    check = innovation(moved, update, ping, model)
    if gated(check, config):  # soundings no particle explains: the prediction alone
        mean, cov = weighted_moments(moved)
        return StepResult(moved, mean, cov, effective_sample_size(moved.weights), innovation=check,
                          counts={"n_gated": 1})
    weighted = reweight(moved, update.log_likelihood, where=f"ping {ping.index}")
    weighted = weighted.tide_updated(update).replace(misfit=update.scale_after(weighted.weights))
    if _needs_tempering(moved, weighted, update, config):
        return _tempered(moved, ping, model, config, update, rng)
    ess = effective_sample_size(weighted.weights)
    if ess >= config.ess_threshold * belief.n_particles:
        mean, cov = weighted_moments(weighted)
        return StepResult(weighted, mean, cov, ess, innovation=check)
    moments = state_moments(weighted)
    bandwidth = kernel_bandwidth(config, ess, belief.n_particles)
    ancestors = resample(weighted.weights, config.resampler, rng=rng)
    parents, copies = np.unique(ancestors, return_counts=True)
    uniform = weighted.take(ancestors)
    if ping.first:  # nothing to redraw from: plain copies (see the module docstring)
        mean, cov = weighted_moments(weighted)
        info = {"parents": parents, "copies": copies, "ancestors": ancestors, "auxiliary": False}
        uniform = shrink_calibration(
            uniform, moments, bandwidth, _kernel_floor(model, config), rng=rng
        )
        return StepResult(uniform, mean, cov, ess, resampled=True, info=info, innovation=check)
    # the children: their parents' previous states with the calibrations moved by the kernel
    # (conditional on the parents' predicted positions, which the moments are of), redrawn. The
    # parents' calibrations are those after this step's heading walk, which the redraw draws
    # again: a child's walk is doubled. Drawing it once (a15f770, reverted) cost wang2019 15 % of
    # RMSE and took its mean final NEES from 2.3 to 228 over 20 runs: the doubled walk is the
    # cloud's only roughening in heading, and stays until a principled one replaces it.
    floor = _kernel_floor(model, config)
    shrunk = shrink_calibration(uniform, moments, bandwidth, floor, rng=rng)
    previous = belief.take(ancestors).replace(calibration=shrunk.calibration)
    children = predict(previous, ping, model, rng=rng)
    child_update = evaluate(children, ping, model, earlier=update)
    measured = children.tide_updated(child_update)
    try:
        new = reweight(
            uniform,
            child_update.log_likelihood - update.log_likelihood[ancestors],
            where=f"ping {ping.index} (IPF children)",
        ).replace(particles=children.particles, calibration=children.calibration, tide=measured.tide,
                  tide_drift=measured.tide_drift)
    except FilterDivergence:
        new = uniform  # no child on the map: keep the copies
    mean, cov = weighted_moments(new)
    info = {"parents": parents, "copies": copies, "ancestors": ancestors, "auxiliary": True}
    return StepResult(
        new, mean, cov, effective_sample_size(new.weights), resampled=True, info=info, innovation=check
    )


def ipf(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: IPFConfig | None = None,
    *,
    model: NavigationModel | None = None,
    rng: np.random.Generator,
    progress: bool = False,
) -> Track:
    """Run the IPF (Han et al. 2020) over a survey (``model``: the navigation model, None: from
    the survey); see the module docstring."""
    return run_particle_filter(
        survey, bathymetry, config or IPFConfig(), ipf_step, method="ipf", rng=rng, model=model,
        progress=progress,
    )  # fmt: skip
