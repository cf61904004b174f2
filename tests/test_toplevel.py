"""The top-level package (issue 23, one door per job): ``tangraph.navigate`` is the library's one
entry point, the very function the CLI calls (tests/cli/test_tracks.py checks that it does),
with what a script needs to call it beside it; and ``import tangraph`` stays fast (its names
load the heavy libraries only when first used)."""

import subprocess
import sys

import tangraph
import tangraph.navigation

#: the names a script needs to navigate a survey from the top level, and where they live
DOOR = {
    "navigate": "tangraph.navigation",
    "read_map": "tangraph.maps",
    "read_survey": "tangraph.survey",
    "NavigationModel": "tangraph.sensors",
    "load_navigation_model": "tangraph.sensors",
    "Track": "tangraph.track",
    "Survey": "tangraph.survey",
    "BathymetryMap": "tangraph.maps",
}


def test_navigate_is_the_one_in_navigation():
    assert tangraph.navigate is tangraph.navigation.navigate


def test_every_name_of_the_door_resolves_to_its_module_s():
    import importlib

    for name, module in DOOR.items():
        assert name in tangraph.__all__
        assert name in dir(tangraph)
        assert getattr(tangraph, name) is getattr(importlib.import_module(module), name), name


def test_every_public_name_resolves_and_all_is_sorted():
    for name in tangraph.__all__:
        getattr(tangraph, name)
    assert tangraph.__all__ == sorted(tangraph.__all__)


def test_import_tangraph_loads_no_heavy_library():
    heavy = ("gtsam", "open3d", "numba", "pyproj", "scipy", "tangraph.navigation", "tangraph.sensors")
    code = (
        "import sys\n"
        "import tangraph\n"
        f"loaded = sorted(m for m in sys.modules if m.split('.')[0] in {heavy!r} or m in {heavy!r})\n"
        "assert not loaded, loaded\n"
        "tangraph.navigate\n"
        "assert 'tangraph.navigation' in sys.modules\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
