"""Faults laid on a clean survey (tangraph.sim.faults): where they go and what they change."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.sim.faults import faulty_pings, offset_start, outlier_blocks
from tangraph.survey import Survey, footprints


def _survey(n: int = 200, beams: int = 5) -> Survey:
    time = np.arange(n, dtype=float)
    pose = np.column_stack([np.arange(n) * 2.0, np.zeros(n), np.full(n, 0.3)])
    forward = np.zeros((n, beams))
    starboard = np.tile(np.linspace(-10, 10, beams), (n, 1))
    return Survey(time=time, dr_pose=pose, vehicle_depth=np.zeros(n), beam_forward=forward,
                  beam_starboard=starboard, beam_depth=np.full((n, beams), 20.0), true_pose=pose)


@pytest.mark.parametrize("fraction", [0.1, 0.2, 0.3])
def test_blocks_cover_the_fraction_asked_without_overlap(fraction):
    survey = _survey()
    spoiled = outlier_blocks(survey, "depth_bias", fraction, rng=np.random.default_rng(1))
    faults = spoiled.meta["faults"]
    assert len(faults) == round(fraction * 200 / 20)
    assert faulty_pings(spoiled).sum() == 20 * len(faults)
    assert all(f["last"] - f["first"] == 19 for f in faults)


def test_footprint_shift_moves_every_footprint_of_a_block_by_the_shift_in_the_world():
    survey = _survey()
    spoiled = outlier_blocks(survey, "footprint_shift", 0.2, rng=np.random.default_rng(2), shift=30.0)
    before = np.stack(footprints(survey.dr_pose, survey.beam_forward, survey.beam_starboard))
    after = np.stack(footprints(spoiled.dr_pose, spoiled.beam_forward, spoiled.beam_starboard))
    bad = faulty_pings(spoiled)
    moved = after - before
    assert np.allclose(moved[:, ~bad], 0.0)
    for fault in spoiled.meta["faults"]:
        block = slice(fault["first"], fault["last"] + 1)
        assert np.allclose(moved[0, block], fault["shift_north"])
        assert np.allclose(moved[1, block], fault["shift_east"])
        assert np.hypot(fault["shift_north"], fault["shift_east"]) == pytest.approx(30.0)
    assert np.array_equal(spoiled.beam_depth, survey.beam_depth)


def test_depth_bias_adds_one_value_per_block_within_its_range():
    survey = _survey()
    spoiled = outlier_blocks(survey, "depth_bias", 0.3, rng=np.random.default_rng(3), bias=(3.0, 10.0))
    change = spoiled.beam_depth - survey.beam_depth
    assert np.allclose(change[~faulty_pings(spoiled)], 0.0)
    for fault in spoiled.meta["faults"]:
        block = change[fault["first"] : fault["last"] + 1]
        assert np.allclose(block, fault["bias"]) and 3.0 <= abs(fault["bias"]) <= 10.0


def test_offset_start_moves_the_whole_dead_reckoning_only():
    survey = _survey()
    moved = offset_start(survey, [150.0, -80.0])
    assert np.allclose(moved.dr_pose[:, :2] - survey.dr_pose[:, :2], [150.0, -80.0])
    assert np.array_equal(moved.true_pose, survey.true_pose)
    assert moved.meta["faults"][0]["kind"] == "start_offset"


@pytest.mark.parametrize(("args", "text"), [
    (("depth_bias", 1.0), "fraction must lie in"),
    (("depth_bias", 0.99), "do not fit"),
    (("sideways", 0.1), "kind must be"),
    (("footprint_shift", 0.1, {"shift": "far"}), "shift must be a number"),
    (("depth_bias", 0.1, {"bias": 5.0}), "bias a range"),
])
def test_bad_settings_are_refused(args, text):
    options = args[2] if len(args) > 2 else {}
    with pytest.raises(TangraphError, match=text):
        outlier_blocks(_survey(), *args[:2], rng=np.random.default_rng(0), **options)
