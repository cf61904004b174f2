"""The exceptions tangraph raises for bad input.

Every error names what was wrong (the file, the variable, the value) so that a user can fix
the input without reading a traceback from deep inside numpy, netCDF4 or gtsam.
"""

from __future__ import annotations

__all__ = ["MapFormatError", "TangraphError"]


class TangraphError(ValueError):
    """Base class of tangraph's input errors (a ``ValueError``)."""


class MapFormatError(TangraphError):
    """A map file or array cannot be read as a bathymetry grid."""
