"""The water-level table (tangraph.formats.waterlevel): a level by date, and bad rows named by line
and column."""

from __future__ import annotations

import datetime as dt

import pytest

from tangraph.formats import read_water_level
from tangraph.survey import SurveyError


def test_read_water_level_refuses_bad_rows(tmp_path):
    p = tmp_path / "level.csv"
    p.write_text("date;waterlevel\n16.01.2025;0.762\n2025-01-18;0,764\n")
    table = read_water_level(p)
    assert table.on(dt.date(2025, 1, 18)) == 0.764
    p.write_text("date;waterlevel\n16.01.2025;high\n")
    with pytest.raises(SurveyError, match="line 2, column 2: 'high' is not a level"):
        read_water_level(p)
    p.write_text("date;waterlevel\n16.13.2025;0.7\n")
    with pytest.raises(SurveyError, match="line 2, column 1: '16.13.2025' is not a date"):
        read_water_level(p)
