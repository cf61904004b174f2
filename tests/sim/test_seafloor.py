"""The world whose seafloor is not the map (:mod:`tangraph.sim.seafloor`): the true seafloor's
random field, and its change since the earlier survey, which may vary in patches."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap
from tangraph.sim.seafloor import SeafloorSettings, changed_seafloor, true_seafloor

AXIS = np.arange(0.0, 4000.0, 10.0)
FLAT = BathymetryMap(AXIS, AXIS, np.full((AXIS.size, AXIS.size), 30.0), name="flat")
TRACK = np.array([[1000.0, 1000.0], [3000.0, 3000.0]])


def _change(settings: SeafloorSettings, seed: int = 4) -> np.ndarray:
    """The seafloor's change since the earlier survey, on a flat map without relief of its own."""
    rng = np.random.default_rng(seed)
    seafloor = true_seafloor(FLAT, TRACK, SeafloorSettings(std=0.0), rng=rng)
    return changed_seafloor(seafloor, settings, rng=rng).depth - seafloor.depth


def test_the_seafloors_field_is_gaussian_and_without_a_change_the_seafloor_stays():
    rng = np.random.default_rng(4)
    seafloor = true_seafloor(FLAT, TRACK, SeafloorSettings(std=0.3, correlation_length=30.0), rng=rng)
    relief = seafloor.depth - 30.0
    assert relief.std() == pytest.approx(0.3, rel=0.05)
    assert np.mean((relief / relief.std()) ** 4) == pytest.approx(3.0, abs=0.3)  # Gaussian kurtosis
    assert changed_seafloor(seafloor, SeafloorSettings(), rng=rng) is seafloor


def test_a_change_in_patches_keeps_its_mean_square_and_has_a_heavy_tail():
    """A change of 0.3 m whose log-std is 1 over patches of 300 m: its kurtosis is about
    ``3 exp(4)`` in expectation (far above a Gaussian's 3 in any draw), its RMS stays near 0.3 m
    (the factor's mean square is 1; a map of a few patches scatters about it), and the worst 5 %
    of 100 m squares change several times more than the median square (``exp(1.645)``, 5.2, for
    a factor constant over a square; measured 3.9-6.5 over eight seeds)."""
    plain = _change(SeafloorSettings(change_std=0.3))
    assert plain.std() == pytest.approx(0.3, rel=0.05)
    rms, kurtosis, spread = [], [], []
    for seed in range(4):
        change = _change(SeafloorSettings(change_std=0.3, patch_scale_std=1.0, patch_length=300.0), seed)
        rms.append(np.sqrt(np.mean(change**2)))
        kurtosis.append(np.mean(change**4) / np.mean(change**2) ** 2)
        n = change.shape[0] // 10 * 10
        squares = change[:n, :n].reshape(n // 10, 10, n // 10, 10).std(axis=(1, 3)).ravel()
        spread.append(np.quantile(squares, 0.95) / np.median(squares))
    assert 0.15 < np.sqrt(np.mean(np.square(rms))) < 0.6
    assert min(kurtosis) > 10.0
    assert min(spread) > 3.0


@pytest.mark.parametrize(("table", "message"), [
    ({"patch_scale_std": -1.0}, "patch_scale_std"),
    ({"patch_scale_std": 1.0}, "patch_scale_std varies the seafloor's change .* give change_std > 0 too"),
])
def test_bad_change_settings_are_refused(table, message):
    with pytest.raises(TangraphError, match=message):
        SeafloorSettings.from_table(table, "scenario [seafloor]")


def test_the_offset_a_gridded_map_keeps_is_its_positioning_over_the_root_of_its_lines():
    # one beam under each ping; three east-going lines 100 m apart, each cell under one line;
    # then the middle line surveyed twice: its cells average two independent errors
    from tangraph.sim.seafloor import PriorMapSettings, _offset
    from tangraph.survey import Survey

    axis = np.arange(0.0, 300.0, 10.0)
    grid = BathymetryMap(axis, axis, np.full((30, 30), 20.0))
    east = np.arange(0.0, 200.0, 5.0)
    rows = [(n, e) for n in (50.0, 150.0, 250.0) for e in east]
    pose = np.column_stack([np.array(rows), np.full(len(rows), np.pi / 2)])
    k = pose.shape[0]
    survey = Survey(time=np.arange(float(k)), dr_pose=pose, vehicle_depth=np.zeros(k),
                    beam_forward=np.zeros((k, 1)), beam_starboard=np.zeros((k, 1)),
                    beam_depth=np.full((k, 1), 20.0), true_pose=pose)
    settings = PriorMapSettings(line_spacing=100.0, speed=2.0, position_std=1.5, position_time=60.0)
    lines = np.repeat([0.0, 1.0, 2.0], east.size)
    std, length = _offset(survey, lines, grid, settings)
    assert std == pytest.approx(1.5) and length == pytest.approx(np.sqrt(240.0 * 100.0))
    twice = np.r_[lines, np.full(east.size, 3.0)]  # the middle line again
    again = Survey(time=np.arange(k + east.size * 1.0), dr_pose=np.r_[pose, pose[east.size:2 * east.size]],
                   vehicle_depth=np.zeros(k + east.size), beam_forward=np.zeros((k + east.size, 1)),
                   beam_starboard=np.zeros((k + east.size, 1)), beam_depth=np.full((k + east.size, 1), 20.0))
    std, length = _offset(again, twice, grid, settings)
    assert std == pytest.approx(1.5 * np.sqrt((1 + 0.5 + 1) / 3))
    assert length == pytest.approx(np.sqrt(240.0 * 100.0 * 4 / 3))
    assert _offset(survey, lines, grid, PriorMapSettings(position_std=0.0)) == (0.0, 0.0)
