"""Fixtures shared by every test package: the real recorded data beside the checkout (the Lake
Caputh runs, the multibeam files), and simulated surveys on the real Merimbula map (the navigation,
map-frame and CLI tests')."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tangraph.maps import load
from tangraph.sim.scenario import load_scenario, simulate
from tangraph.survey import write_survey
from tests.formats.recorded_files import GSF, XTF

#: ``../shared/data`` beside the checkout (not part of the project; see its README)
SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def caputh() -> Path:
    """The Lake Caputh RiverSurveyor runs; the test is skipped when the folder is absent."""
    folder = SHARED_DATA / "caputh"
    if not (folder / "20250327110103.sum").is_file():
        pytest.skip(f"real data folder {folder} is absent (it sits beside the checkout as ../shared)")
    return folder


@pytest.fixture(scope="session")
def multibeam() -> Path:
    """The real multibeam files; the test is skipped when the folder is absent."""
    folder = SHARED_DATA / "multibeam"
    if not ((folder / XTF).is_file() and (folder / GSF).is_file()):
        pytest.skip(f"real data folder {folder} is absent (it sits beside the checkout as ../shared)")
    return folder


@pytest.fixture(scope="module")
def wang_survey():
    """The wang2019 scenario on the real Merimbula map: 280 pings over 1.7 km."""
    bathymetry = load("merimbula")
    survey = simulate(load_scenario("wang2019"), rng=np.random.default_rng(3), bathymetry=bathymetry, seed=3)
    return survey, bathymetry


@pytest.fixture(scope="module")
def survey_file(wang_survey, tmp_path_factory):
    path = tmp_path_factory.mktemp("nav") / "wang.nc"
    write_survey(wang_survey[0], path)
    return path


@pytest.fixture(scope="module")
def merimbula():
    return load("merimbula")


@pytest.fixture(scope="module")
def simulated(merimbula):
    return simulate(load_scenario("wang2019"), rng=np.random.default_rng(3), bathymetry=merimbula, seed=3)
