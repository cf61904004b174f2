"""Bathymetry maps: the grid, its readers and writers, the catalogue, synthetic terrain,
terrain statistics and the Open3D bridge."""

from tangraph.maps.catalogue import CatalogueEntry, catalogue, catalogue_path, list_maps, load, load_any
from tangraph.maps.grid import BathymetryMap
from tangraph.maps.io import Soundings, read_map, read_soundings, write_map
from tangraph.maps.projection import from_lonlat, local_crs, project_geographic_grid, to_lonlat

__all__ = [
    "BathymetryMap",
    "CatalogueEntry",
    "Soundings",
    "catalogue",
    "catalogue_path",
    "from_lonlat",
    "list_maps",
    "load",
    "load_any",
    "local_crs",
    "project_geographic_grid",
    "read_map",
    "read_soundings",
    "to_lonlat",
    "write_map",
]
