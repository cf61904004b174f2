"""Fixtures shared by every test package: the real recorded data beside the checkout."""

from __future__ import annotations

from pathlib import Path

import pytest

#: ``../shared/data`` beside the checkout (not part of the project; see its README)
SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def caputh() -> Path:
    """The Lake Caputh RiverSurveyor runs; the test is skipped when the folder is absent."""
    folder = SHARED_DATA / "caputh"
    if not (folder / "20250327110103.sum").is_file():
        pytest.skip(f"real data folder {folder} is absent (it sits beside the checkout as ../shared)")
    return folder
