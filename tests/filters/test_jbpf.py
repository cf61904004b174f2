"""JBPF (tangraph.filters.jbpf): the bootstrap step, with jitter on the pings it resamples only."""

from __future__ import annotations

import numpy as np

from tangraph.filters import JBPFConfig
from tangraph.filters.belief import initial_belief
from tangraph.filters.jbpf import jbpf_step
from tangraph.filters.model import FilterModel, survey_pings
from tangraph.filters.pf import pf_step
from tangraph.filters.steps import predict
from tests.filters.synthetic import multibeam_survey, navigation, rough_map

MAP = rough_map(0)
SURVEY = multibeam_survey(MAP, seed=1, pings=30)
MODEL = navigation(SURVEY, initial_position_std=20.0, sounding_std=0.5)


def test_jbpf_jitters_only_the_pings_it_resamples():
    model = FilterModel.from_model(MODEL, MAP)
    ping = survey_pings(SURVEY)[1]
    belief = initial_belief(SURVEY.dr_pose[0, :2], 10.0, 300, rng=np.random.default_rng(0))
    kept = jbpf_step(
        belief, ping, model, JBPFConfig(n_particles=300, ess_threshold=0.0, tempering=False),
        rng=np.random.default_rng(1),
    )  # fmt: skip
    moved = predict(belief, ping, model, rng=np.random.default_rng(1)).particles
    assert not kept.resampled
    np.testing.assert_array_equal(kept.belief.particles, moved)
    config = JBPFConfig(n_particles=300, ess_threshold=1.0, jitter_std=2.0)
    jittered = jbpf_step(belief, ping, model, config, rng=np.random.default_rng(1))
    assert jittered.resampled
    assert np.unique(jittered.belief.particles, axis=0).shape[0] == 300  # copies pulled apart
    # exactly the bootstrap step, then N(0, jitter_std^2) on its resampled particles
    rng = np.random.default_rng(1)
    plain = pf_step(belief, ping, model, config, rng=rng)
    np.testing.assert_array_equal(jittered.belief.log_weights, plain.belief.log_weights)
    np.testing.assert_array_equal(jittered.mean, plain.mean)
    assert jittered.ess == plain.ess
    np.testing.assert_allclose(
        jittered.belief.particles, plain.belief.particles + 2.0 * rng.standard_normal((300, 2))
    )
