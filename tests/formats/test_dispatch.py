"""One door to every survey importer (tangraph.formats.dispatch): the formats, and what each refuses."""

from __future__ import annotations

import pytest


def test_survey_import_is_the_library_s_import_survey(tmp_path):
    from tangraph.errors import TangraphError
    from tangraph.formats import SURVEY_FORMATS, import_survey

    assert list(SURVEY_FORMATS) == ["csv-xyz", "sontek-sum", "xtf", "gsf"]
    with pytest.raises(TangraphError, match="format 'xtf' takes no timezone"):
        import_survey("xtf", [tmp_path / "a.xtf"], crs="EPSG:32610", timezone="UTC")
    with pytest.raises(TangraphError, match=r"format 'csv-xyz' takes two files \(navigation log, "):
        import_survey("csv-xyz", [tmp_path / "nav.csv"])
    with pytest.raises(TangraphError, match="unknown survey format 'kmall'"):
        import_survey("kmall", [tmp_path / "a.kmall"])
