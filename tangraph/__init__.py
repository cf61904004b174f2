"""tangraph: terrain-aided navigation of AUVs on bathymetry maps."""

from importlib.metadata import PackageNotFoundError, version

from tangraph.errors import MapFormatError, TangraphError
from tangraph.maps import BathymetryMap
from tangraph.survey import Survey, read_survey, write_survey

try:
    __version__ = version("tangraph")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0+unknown"

__all__ = [
    "BathymetryMap",
    "MapFormatError",
    "Survey",
    "TangraphError",
    "__version__",
    "read_survey",
    "write_survey",
]
