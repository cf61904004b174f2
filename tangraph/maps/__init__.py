"""Bathymetry maps: the grid, its readers and writers, the catalogue, synthetic terrain,
terrain statistics and the Open3D bridge."""

from tangraph.maps.grid import BathymetryMap

__all__ = ["BathymetryMap"]
