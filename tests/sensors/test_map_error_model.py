"""The map's error as the estimators model it (tangraph.sensors.map_error_model): from the map or
the model, split by scale, the seafloor's change since the map as a field of its own, the offset's
part taken out through the slope; bad statements refused."""

from __future__ import annotations

import numpy as np
import pytest

from tangraph.errors import TangraphError
from tangraph.maps import BathymetryMap
from tangraph.sensors import MapError, NavigationModel, map_error, matern_correlation, sounding_variances
from tests.sensors.terrain_cases import FLAT, scattered_survey


def test_the_map_error_comes_from_the_map_or_the_model():
    error = map_error(FLAT, NavigationModel(map_std=0.4))
    assert error.correlation_length == 10.0  # one cell
    np.testing.assert_allclose(error.std_at(55.0, 55.0), 0.4)
    assert np.isnan(error.std_at(-50.0, 55.0))
    assert map_error(FLAT, NavigationModel()).is_zero
    assert map_error(FLAT, NavigationModel(map_correlation_length=35.0)).correlation_length == 35.0


def test_a_map_with_gaps_splits_its_error_by_scale():
    """Well-surveyed cells' error at the cell scale everywhere, the excess of the interpolated
    ones over it correlated over the map's correlation length; the variance is kept."""
    std = np.where(np.arange(100)[None, :] < 50, 0.1, 0.4) * np.ones((100, 1))
    gappy = FLAT.replace(depth_std=std, correlation_length=40.0)
    cell, excess = map_error(gappy, NavigationModel()).components()
    assert (cell.correlation_length, excess.correlation_length) == (10.0, 40.0)
    np.testing.assert_allclose(cell.std, 0.1)
    np.testing.assert_allclose(cell.std**2 + excess.std**2, std**2)
    assert np.all(excess.std[:, :50] == 0.0)
    # a uniform std, or a range of a cell: one field
    uniform = map_error(FLAT, NavigationModel(map_std=0.2, map_correlation_length=30.0)).components()
    assert len(uniform) == 1 and uniform[0].correlation_length == 30.0
    assert len(map_error(gappy.replace(correlation_length=10.0), NavigationModel()).components()) == 1


def test_the_change_since_the_map_is_a_field_of_its_own():
    """The model's change adds to every cell in quadrature, as a uniform field of its own range
    beside the map's own statement, which keeps its split; the offset leaves the change whole."""
    std = np.where(np.arange(100)[None, :] < 50, 0.1, 0.4) * np.ones((100, 1))
    gappy = FLAT.replace(depth_std=std, correlation_length=40.0)
    error = map_error(gappy, NavigationModel(map_change_std=0.2, map_change_length=25.0))
    np.testing.assert_allclose(error.std**2, std**2 + 0.04)
    cell, excess, change = error.components()
    assert [p.correlation_length for p in (cell, excess, change)] == [10.0, 40.0, 25.0]
    np.testing.assert_allclose(cell.std**2 + excess.std**2, std**2)
    np.testing.assert_allclose(change.std, 0.2)
    np.testing.assert_allclose(error.own.std, std)
    # the map's own correlation length when the change states none; none at all on a perfect map
    assert map_error(gappy, NavigationModel(map_change_std=0.2)).change_length == 40.0
    alone = map_error(FLAT, NavigationModel(map_change_std=0.2)).components()
    assert len(alone) == 1 and alone[0].correlation_length == 10.0
    # more error shared: a sounding among others counts for less
    points = np.array([[300.0, 300.0], [300.0, 310.0], [310.0, 300.0]])
    survey = scattered_survey(points)
    told = NavigationModel(sounding_std=0.1, map_std=0.1, map_change_std=0.2, map_change_length=50.0)
    added = sounding_variances(survey, FLAT, told) - sounding_variances(survey, FLAT,
                                                                        told.replace(map_change_std=0))
    d = np.sqrt(np.sum((points[:, None, :] - points[None, :, :]) ** 2, axis=-1))
    np.testing.assert_allclose(added[:, 0], 0.04 * matern_correlation(d, 50.0).sum(axis=1), rtol=0.05)
    plane = BathymetryMap(FLAT.north, FLAT.east, 30.0 + 0.1 * FLAT.north[:, None] + 0 * FLAT.east)
    offset = map_error(plane, NavigationModel(map_std=0.3, map_change_std=0.2)).without_offset(2.0)
    np.testing.assert_allclose(offset.std**2, 0.3**2 - (2.0 * 0.1) ** 2 + 0.2**2, rtol=1e-9)
    assert offset.change_std == 0.2


def test_a_change_larger_than_the_std_it_is_part_of_is_refused():
    with pytest.raises(TangraphError, match="change since the map .0.3 m. is part of its std"):
        MapError(FLAT, np.full(FLAT.shape, 0.2), 20.0, change_std=0.3)
    with pytest.raises(TangraphError, match="change_std and change_length must be >= 0"):
        MapError(FLAT, np.full(FLAT.shape, 0.2), 20.0, change_std=-0.1)


def test_the_offset_takes_its_part_of_the_stated_error_out_through_the_slope():
    # a plane of slope 0.1 whose cells state 0.3 m and the 2 m positioning error's 0.2 m through
    # the slope: held apart, the offset leaves 0.3 m; where the offset would explain more than
    # three quarters of the stated variance, half the stated std is kept
    axis = np.arange(0.0, 200.0, 10.0)
    plane = BathymetryMap(axis, axis, 30.0 + 0.1 * axis[:, None] + 0 * axis)
    stated = np.hypot(0.3, 2.0 * 0.1)
    error = MapError(plane, np.full(plane.shape, stated), 30.0)
    np.testing.assert_allclose(error.without_offset(2.0).std, 0.3, rtol=1e-9)
    assert error.without_offset(0.0) is error
    np.testing.assert_allclose(error.without_offset(20.0).std, 0.5 * stated, rtol=1e-9)
    assert error.without_offset(2.0).correlation_length == 30.0
