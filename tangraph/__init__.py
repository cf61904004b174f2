"""tangraph: terrain-aided navigation of AUVs on bathymetry maps."""

import importlib
from importlib.metadata import PackageNotFoundError, version

from tangraph.errors import MapFormatError, TangraphError

try:
    __version__ = version("tangraph")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

#: names imported when first used, so that ``import tangraph`` (and ``tangraph --version``)
#: stays fast: the heavy libraries (Open3D, numba, GTSAM) load with the modules that use them
_WHERE = {
    "BathymetryMap": "tangraph.maps.grid",
    "Survey": "tangraph.survey",
    "read_survey": "tangraph.survey",
    "write_survey": "tangraph.survey",
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
    "BathymetryMap",
    "MapFormatError",
    "Survey",
    "TangraphError",
    "__version__",
    "read_survey",
    "write_survey",
]
