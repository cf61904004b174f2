"""Bathymetry maps: the grid, its readers and writers, the catalogue, synthetic terrain,
terrain statistics and the Open3D bridge."""

import importlib

# eager: the submodule ``catalogue`` would otherwise shadow the function of that name once imported
from tangraph.maps.catalogue import (
    CatalogueEntry,
    catalogue,
    catalogue_path,
    list_maps,
    load,
    load_any,
)

#: every public name and the module that defines it; imported when first used, so that
#: ``import tangraph.maps`` does not load Open3D, numba or pyproj before they are needed
_WHERE = {
    "BathymetryMap": "tangraph.maps.grid",
    "HAN2020_AREAS": "tangraph.maps.synthetic",
    "SoundingGrid": "tangraph.maps.mesh",
    "Soundings": "tangraph.maps.io",
    "TerrainScene": "tangraph.maps.mesh",
    "block_reduce": "tangraph.maps.gridding",
    "cast_rays": "tangraph.maps.mesh",
    "crlb": "tangraph.maps.statistics",
    "fill_gaps": "tangraph.maps.gridding",
    "fisher_information": "tangraph.maps.statistics",
    "flat_with_noise": "tangraph.maps.synthetic",
    "fractal": "tangraph.maps.synthetic",
    "from_lonlat": "tangraph.maps.projection",
    "from_mesh": "tangraph.maps.mesh",
    "grid_soundings": "tangraph.maps.mesh",
    "grid_surveys": "tangraph.maps.gridding",
    "han2020_chart": "tangraph.maps.synthetic",
    "local_crs": "tangraph.maps.projection",
    "polar_chart": "tangraph.maps.synthetic",
    "project_geographic_grid": "tangraph.maps.projection",
    "raycasting_scene": "tangraph.maps.mesh",
    "read_map": "tangraph.maps.io",
    "read_mesh": "tangraph.maps.mesh",
    "read_soundings": "tangraph.maps.io",
    "region_entropy": "tangraph.maps.statistics",
    "ridges": "tangraph.maps.synthetic",
    "roughness": "tangraph.maps.statistics",
    "seamounts": "tangraph.maps.synthetic",
    "slope": "tangraph.maps.statistics",
    "terrain_entropy": "tangraph.maps.statistics",
    "terrain_std": "tangraph.maps.statistics",
    "to_lonlat": "tangraph.maps.projection",
    "to_mesh": "tangraph.maps.mesh",
    "triangles_to_map": "tangraph.maps.mesh",
    "window_information": "tangraph.maps.statistics",
    "write_map": "tangraph.maps.io",
    "write_mesh": "tangraph.maps.mesh",
}


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(_WHERE[name]), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_WHERE))


__all__ = [
    "HAN2020_AREAS",
    "BathymetryMap",
    "CatalogueEntry",
    "SoundingGrid",
    "Soundings",
    "TerrainScene",
    "block_reduce",
    "cast_rays",
    "catalogue",
    "catalogue_path",
    "crlb",
    "fill_gaps",
    "fisher_information",
    "flat_with_noise",
    "fractal",
    "from_lonlat",
    "from_mesh",
    "grid_soundings",
    "grid_surveys",
    "han2020_chart",
    "list_maps",
    "load",
    "load_any",
    "local_crs",
    "polar_chart",
    "project_geographic_grid",
    "raycasting_scene",
    "read_map",
    "read_mesh",
    "read_soundings",
    "region_entropy",
    "ridges",
    "roughness",
    "seamounts",
    "slope",
    "terrain_entropy",
    "terrain_std",
    "to_lonlat",
    "to_mesh",
    "triangles_to_map",
    "window_information",
    "write_map",
    "write_mesh",
]
