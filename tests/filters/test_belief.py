"""The particle belief (tangraph.filters.belief): its moments, read-only arrays, mismatched arrays
refused, the start's centre, spread and count checked, a held fix carried through resampling."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.filters import fixes
from tangraph.filters.belief import Belief, initial_belief, weighted_moments
from tests.filters.synthetic import gaussian_fix as _fix


def one_particle_with_all_the_weight():
    particles = np.array([[1.0, 2.0], [30.0, 40.0], [-5.0, 7.0]])
    logw = np.log(np.array([0.0, 1.0, 0.0]) + 1e-300)
    return Belief(
        particles, logw - np.log(np.exp(logw).sum()), np.zeros(3), 0.0, np.zeros((3, 0)), np.zeros(0)
    )


def test_moments_of_a_certain_belief():
    mean, cov = weighted_moments(one_particle_with_all_the_weight())
    np.testing.assert_allclose(mean, [30.0, 40.0])
    np.testing.assert_allclose(cov, np.zeros((2, 2)), atol=1e-200)


def test_belief_arrays_are_read_only():
    b = initial_belief([0.0, 0.0], 1.0, 5, rng=np.random.default_rng(0))
    with pytest.raises(ValueError):
        b.particles[0, 0] = 1.0


def belief_arrays(n=5, length=0, **changes):
    arrays = {
        "particles": np.zeros((n, 2)),
        "log_weights": np.full(n, -np.log(n)),
        "tide": np.zeros(n),
        "tide_var": 0.0,
        "history": np.zeros((n, length)),
        "measured": np.zeros(length),
    }
    return arrays | changes


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"particles": np.zeros((3, 2))}, r"log_weights must have shape \(3,\).*got \(5,\)"),
        ({"particles": np.zeros((5, 3))}, r"particles must have shape \(N, 2\), got \(5, 3\)"),
        ({"particles": np.zeros(10)}, r"particles must have shape \(N, 2\), got \(10,\)"),
        ({"tide": np.zeros(4)}, r"tide must have shape \(5,\).*got \(4,\)"),
        ({"history": np.zeros((4, 3)), "measured": np.zeros(3)}, r"history must have shape \(5, L\)"),
        ({"history": np.zeros((5, 3)), "measured": np.zeros(2)}, r"measured must have shape \(3,\)"),
        ({"history": np.zeros(5), "measured": np.zeros(0)}, r"history must have shape \(5, L\)"),
        ({"tide_var": -1.0}, "tide_var must be >= 0, got -1.0"),
        ({"n_history": 1}, "n_history must be <= L = 0, got 1"),
        ({"n_fixes": -1}, "n_fixes must be an integer >= 0, got -1"),
    ],
)
def test_a_belief_of_mismatched_arrays_is_refused(changes, message):
    """Particles (3, 2) with five weights used to give garbage moments (the compiled loop read
    past the particles); every per-particle array must have the particles' N."""
    with pytest.raises(TangraphError, match=f"Belief.{message}"):
        Belief(**belief_arrays(**changes))


def test_moments_refuse_a_replaced_belief_of_mismatched_arrays():
    belief = Belief(**belief_arrays()).replace(particles=np.zeros((3, 2)))  # replace does not check
    with pytest.raises(TangraphError, match=r"weighted_moments: .*\(3, 2\), \(5,\)"):
        weighted_moments(belief)


@pytest.mark.parametrize("centre", [[1.0, 2.0, 0.3], [[1.0, 2.0]], [np.nan, 0.0], 5.0, "here"])
def test_initial_belief_wants_a_position_not_a_pose(centre):
    with pytest.raises(TangraphError, match=r"initial_belief: centre must be a .*\(north, east\) position"):
        initial_belief(centre, 1.0, 5, rng=np.random.default_rng(0))


@pytest.mark.parametrize(("name", "value"), [("std", -1.0), ("std", np.nan), ("n", 0), ("n", 2.5)])
def test_initial_belief_names_a_bad_spread_or_count(name, value):
    args = {"std": 1.0, "n": 5} | {name: value}
    with pytest.raises(TangraphError, match=f"initial_belief: {name} must be"):
        initial_belief([0.0, 0.0], args["std"], args["n"], rng=np.random.default_rng(0))


def test_a_held_fixs_anchor_follows_the_particles_through_resampling():
    belief = initial_belief([0.0, 0.0], 5.0, 6, rng=np.random.default_rng(0))
    held = fixes.HeldFix(_fix([1.0, 2.0], 1.0), 9, anchor=belief.particles.copy())
    index = np.array([5, 5, 0, 1, 2, 2])
    taken = belief.replace(held=held).take(index)
    np.testing.assert_array_equal(taken.held.anchor, belief.particles[index])
    assert taken.held.index == 9 and belief.take(index).held is None
