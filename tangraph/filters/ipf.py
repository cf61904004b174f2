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
:meth:`~tangraph.filters.MotionModel.predict`): children would be copies of their parents with
ratio 1, so a resampling there is plain (copies, equal weights; ``info["auxiliary"]`` False), as
in the bootstrap PF: the estimate and ``ess`` are those of the weighted cloud before it. The copies
separate at the next ping's prediction.

Otherwise the estimate is the weighted mean and second moment of the cloud the step returns, and
the step's ``ess`` is that cloud's (after the children's re-weighting: the weights the estimate's
Monte Carlo error depends on). If no child can be weighted (every child off the map) the step
falls back to plain copies.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from tangraph.filters.config import ParticleConfig
from tangraph.filters.core import (
    Belief,
    FilterModel,
    StepResult,
    reweight,
    run_particle_filter,
    weighted_moments,
)
from tangraph.filters.likelihood import FilterDivergence, effective_sample_size
from tangraph.filters.model import Ping
from tangraph.filters.resampling import resample
from tangraph.maps.grid import BathymetryMap
from tangraph.survey import Survey
from tangraph.track import Track

__all__ = ["IPFConfig", "ipf", "ipf_step"]


@dataclasses.dataclass(frozen=True)
class IPFConfig(ParticleConfig):
    """Settings of the IPF: those of :class:`~tangraph.filters.ParticleConfig`, with Han et
    al.'s replay particle count (2000) as default."""

    n_particles: int = 2000


def ipf_step(
    belief: Belief, ping: Ping, model: FilterModel, config: ParticleConfig, *, rng: np.random.Generator
) -> StepResult:
    """One IPF step (see the module docstring)."""
    moved = model.motion.predict(belief.particles, ping, rng=rng)
    if ping.n_soundings == 0:
        predicted = belief.replace(particles=moved)
        mean, cov = weighted_moments(predicted)
        return StepResult(predicted, mean, cov, effective_sample_size(predicted.weights))
    update = model.terrain.evaluate(moved, belief.tide, belief.tide_var, ping)
    weighted = reweight(belief, update.log_likelihood, where=f"ping {ping.index}").replace(
        particles=moved, tide=update.tide, tide_var=update.tide_var
    )
    ess = effective_sample_size(weighted.weights)
    if ess >= config.ess_threshold * belief.n_particles:
        mean, cov = weighted_moments(weighted)
        return StepResult(weighted, mean, cov, ess)
    ancestors = resample(weighted.weights, config.resampler, rng=rng)
    parents, copies = np.unique(ancestors, return_counts=True)
    uniform = weighted.take(ancestors)
    if ping.first:  # nothing to redraw from: plain copies (see the module docstring)
        mean, cov = weighted_moments(weighted)
        info = {"parents": parents, "copies": copies, "ancestors": ancestors, "auxiliary": False}
        return StepResult(uniform, mean, cov, ess, resampled=True, info=info)
    children = model.motion.predict(belief.particles[ancestors], ping, rng=rng)
    child_update = model.terrain.evaluate(children, belief.tide[ancestors], belief.tide_var, ping)
    try:
        new = reweight(
            uniform,
            child_update.log_likelihood - update.log_likelihood[ancestors],
            where=f"ping {ping.index} (IPF children)",
        ).replace(particles=children, tide=child_update.tide)
    except FilterDivergence:
        new = uniform  # no child on the map: keep the copies
    mean, cov = weighted_moments(new)
    info = {"parents": parents, "copies": copies, "ancestors": ancestors, "auxiliary": True}
    return StepResult(new, mean, cov, effective_sample_size(new.weights), resampled=True, info=info)


def ipf(
    survey: Survey,
    bathymetry: BathymetryMap,
    config: IPFConfig | None = None,
    *,
    rng: np.random.Generator,
    progress: bool = False,
) -> Track:
    """Run the IPF (Han et al. 2020) over a survey; see the module docstring."""
    return run_particle_filter(
        survey, bathymetry, config or IPFConfig(), ipf_step, method="ipf", rng=rng, progress=progress
    )
