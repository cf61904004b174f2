"""tangraph: terrain-aided navigation of AUVs on bathymetry maps."""

from importlib.metadata import PackageNotFoundError, version

from tangraph._lazy import lazy_names
from tangraph.errors import MapFormatError, TangraphError

try:
    __version__ = version("tangraph")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

#: names imported when first used, so that ``import tangraph`` (and ``tangraph --version``)
#: stays fast: the heavy libraries (Open3D, numba, GTSAM) load with the modules that use them
#: (the one door, issue 23: ``tangraph.navigate`` and what a script needs to call it)
_WHERE = {
    "BathymetryMap": "tangraph.maps.grid",
    "NavigationModel": "tangraph.sensors",
    "Survey": "tangraph.survey",
    "Track": "tangraph.track",
    "load_navigation_model": "tangraph.sensors",
    "navigate": "tangraph.navigation",
    "read_map": "tangraph.maps.io",
    "read_survey": "tangraph.survey",
    "write_survey": "tangraph.survey",
}


__getattr__, __dir__ = lazy_names(globals(), _WHERE)

__all__ = [
    "BathymetryMap",
    "MapFormatError",
    "NavigationModel",
    "Survey",
    "TangraphError",
    "Track",
    "__version__",
    "load_navigation_model",
    "navigate",
    "read_map",
    "read_survey",
    "write_survey",
]
