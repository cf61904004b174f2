"""One door for every recording: :func:`import_survey` picks the reader of a format by its name.

:data:`SURVEY_FORMATS` says, per format, which reader reads it, which of the readers' options it
takes and how many files; ``tangraph survey import --format NAME`` is this function.
"""

from __future__ import annotations

import dataclasses
import importlib
import os
from collections.abc import Sequence

from tangraph.errors import TangraphError
from tangraph.survey import Survey

__all__ = ["SURVEY_FORMATS", "SurveyFormat", "import_survey"]


@dataclasses.dataclass(frozen=True)
class SurveyFormat:
    """A format of recorded surveys: its reader (``module:function`` in :mod:`tangraph.formats`),
    the keyword options it takes (``crs`` in every one) and its file count (None: one or more)."""

    reader: str
    options: tuple[str, ...]
    files: int | None
    files_text: str = ""

    def read(self, files: Sequence[str | os.PathLike], options: dict) -> Survey:
        module, _, function = self.reader.partition(":")
        # looked up at each call, so that a replaced reader (a test's) is the one called
        reader = getattr(importlib.import_module(f"tangraph.formats.{module}"), function)
        return reader(*files, **options) if self.files is not None else reader(list(files), **options)


#: the formats :func:`import_survey` reads, by name
SURVEY_FORMATS: dict[str, SurveyFormat] = {
    "csv-xyz": SurveyFormat(
        "csv_xyz:import_csv_xyz",
        ("crs", "timezone", "columns", "header", "time_format", "sign", "units"),
        2, "two files (navigation log, soundings)",
    ),
    "sontek-sum": SurveyFormat(
        "sontek:import_sontek_sum",
        ("crs", "timezone", "water_level", "water_level_interpolate", "draft", "dr_heading",
         "declination_deg"),
        None,
    ),
    "xtf": SurveyFormat("xtf:import_xtf", ("crs",), 1, "one file"),
    "gsf": SurveyFormat("gsf:import_gsf", ("crs",), 1, "one file"),
}


def import_survey(format: str, files: Sequence[str | os.PathLike], **options) -> Survey:
    """Read a survey recorded in ``format`` (a key of :data:`SURVEY_FORMATS`) from ``files``.

    ``options`` go to the format's reader (:func:`~tangraph.formats.import_csv_xyz`,
    :func:`~tangraph.formats.import_sontek_sum`, :func:`~tangraph.formats.import_xtf`,
    :func:`~tangraph.formats.import_gsf`); an option the format does not take, or the wrong
    number of files, is refused (:class:`~tangraph.errors.TangraphError`) before any file is read.
    """
    if format not in SURVEY_FORMATS:
        raise TangraphError(f"unknown survey format {format!r}: one of {', '.join(SURVEY_FORMATS)}")
    kind = SURVEY_FORMATS[format]
    wrong = [k for k in options if k not in kind.options]
    if wrong:
        raise TangraphError(
            f"format {format!r} takes no {', '.join(wrong)} (it takes {', '.join(kind.options)})"
        )
    if kind.files is not None and len(files) != kind.files:
        raise TangraphError(f"format {format!r} takes {kind.files_text}, got {len(files)}")
    return kind.read(files, options)
