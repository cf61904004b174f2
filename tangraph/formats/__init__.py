"""Readers of files recorded by instruments, each turning a recording into a `Survey`.

- :mod:`tangraph.formats.csv_xyz`: a CSV navigation log and an XYZ soundings file;
- :mod:`tangraph.formats.sontek`: SonTek RiverSurveyor (M9, S5) summary exports (``.sum``);
- :mod:`tangraph.formats.waterlevel`: water-level tables that refer depths to a common datum;
- :mod:`tangraph.formats.dispatch`: :func:`import_survey`, the reader of a format picked by its name.
"""

from tangraph.formats.csv_xyz import import_csv_xyz
from tangraph.formats.dispatch import SURVEY_FORMATS, SurveyFormat, import_survey
from tangraph.formats.gsf import import_gsf
from tangraph.formats.sontek import SontekRecord, import_sontek_sum, read_sontek_sum
from tangraph.formats.waterlevel import WaterLevel, read_water_level
from tangraph.formats.xtf import import_xtf

__all__ = [
    "SURVEY_FORMATS",
    "SontekRecord",
    "SurveyFormat",
    "WaterLevel",
    "import_csv_xyz",
    "import_gsf",
    "import_sontek_sum",
    "import_survey",
    "import_xtf",
    "read_sontek_sum",
    "read_water_level",
]
