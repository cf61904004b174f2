"""Water-level tables: the level of a lake or river by date, to refer depths to one datum.

A depth below the surface on a day is ``level(day) - bottom elevation``; the depth below the
table's zero (the common datum of every day) is therefore ``depth - level(day)``.
"""

from __future__ import annotations

import csv
import dataclasses
import datetime as dt
import os
from pathlib import Path

import numpy as np

from tangraph.survey import SurveyError

__all__ = ["WaterLevel", "read_water_level"]

_DATE_FORMATS = ("%d.%m.%Y", "%Y-%m-%d", "%d/%m/%Y")


@dataclasses.dataclass(frozen=True)
class WaterLevel:
    """Water levels (m above the table's zero) by date, ascending."""

    path: str
    dates: tuple[dt.date, ...]
    levels: tuple[float, ...]

    def on(self, day: dt.date, *, interpolate: bool = False) -> float:
        """The level on ``day``: the table's value, or with ``interpolate`` the linear
        interpolation between the nearest dates before and after it.

        Raises
        ------
        SurveyError
            The table has no entry for the day (and ``interpolate`` is off, or the day lies
            outside the table's dates).
        """
        if day in self.dates:
            return self.levels[self.dates.index(day)]
        first, last = self.dates[0], self.dates[-1]
        if not interpolate or not first < day < last:
            hint = (
                f"the table runs from {first} to {last}"
                if interpolate
                else "pass water_level_interpolate=True (CLI: --water-level-interpolate) to "
                "interpolate between the neighbouring dates"
            )
            raise SurveyError(f"{self.path}: no water level for {day.isoformat()}; {hint}")
        days = np.array([d.toordinal() for d in self.dates], float)
        return float(np.interp(day.toordinal(), days, np.array(self.levels)))


def read_water_level(path: str | os.PathLike) -> WaterLevel:
    """Read a table of ``date, level`` rows (header row; ``;``, ``,`` or tab separated; dates as
    ``day.month.year``, ISO ``year-month-day`` or ``day/month/year``; levels in metres).

    Examples
    --------
    >>> import tempfile, datetime
    >>> p = Path(tempfile.mkdtemp()) / "level.csv"
    >>> _ = p.write_text("date;waterlevel\\n16.01.2025;0.762\\n18.01.2025;0.764\\n")
    >>> read_water_level(p).on(datetime.date(2025, 1, 17), interpolate=True)
    0.763
    """
    p = Path(path)
    if not p.is_file():
        raise FileNotFoundError(f"water-level file {p} does not exist")
    text = p.read_text(encoding="utf-8-sig", errors="replace")
    rows = [(i + 1, line) for i, line in enumerate(text.splitlines()) if line.strip()]
    if len(rows) < 2:
        raise SurveyError(f"{p}: a water-level table needs a header and at least one row")
    delimiter = next((d for d in ";\t," if d in rows[0][1]), None)
    if delimiter is None:
        raise SurveyError(f"{p}, line {rows[0][0]}: header {rows[0][1]!r} has no ';', ',' or tab")
    entries: dict[dt.date, float] = {}
    for number, fields in ((n, next(csv.reader([line], delimiter=delimiter))) for n, line in rows[1:]):
        if len(fields) < 2:
            raise SurveyError(f"{p}, line {number}: expected date{delimiter}level, got {fields!r}")
        day = _date(fields[0].strip(), p, number)
        try:
            level = float(fields[1].strip().replace(",", "."))
        except ValueError:
            raise SurveyError(
                f"{p}, line {number}, column 2: {fields[1]!r} is not a level in metres"
            ) from None
        if not np.isfinite(level):
            raise SurveyError(f"{p}, line {number}, column 2: level {fields[1]!r} is not finite")
        if day in entries and entries[day] != level:
            raise SurveyError(f"{p}, line {number}: {day} is listed twice with different levels")
        entries[day] = level
    dates = tuple(sorted(entries))
    return WaterLevel(str(p), dates, tuple(entries[d] for d in dates))


def _date(text: str, path: Path, line: int) -> dt.date:
    for fmt in _DATE_FORMATS:
        try:
            return dt.datetime.strptime(text, fmt).date()
        except ValueError:
            continue
    raise SurveyError(f"{path}, line {line}, column 1: {text!r} is not a date (day.month.year or ISO)")
