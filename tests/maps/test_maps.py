"""The maps package (tangraph.maps): its modules one role each, short, and below the surveys
(issue 23); its names, ``grid_surveys`` among them, found when first asked for, without loading
the surveys."""

import ast
import subprocess
import sys
from pathlib import Path

import tangraph
import tangraph.maps

PACKAGE = Path(tangraph.__file__).parent
MAPS = sorted((PACKAGE / "maps").glob("*.py"))
GRIDDING = [PACKAGE / "gridding_surveys.py", PACKAGE / "gridding_files.py"]
#: functions longer than 80 lines, and why they stay so
LONG = {"read_map": "its documented options alone take 79 lines"}


def _imports(path: Path) -> set[str]:
    """Every module a file imports, at module level or inside functions."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module:
            found.add(node.module)
            found.update(f"{node.module}.{alias.name}" for alias in node.names)
    return found


def test_the_maps_never_import_the_surveys():
    above = ("tangraph.survey", "tangraph.gridding_surveys", "tangraph.gridding_files", "tangraph.eval")
    for path in MAPS:
        assert not {name for name in _imports(path) if name.startswith(above)}, path.name


def test_importing_every_map_module_and_name_loads_no_survey():
    names = [name for name in tangraph.maps.__all__ if name != "grid_surveys"]
    code = (
        "import importlib, pkgutil, sys\n"
        "import tangraph.maps as maps\n"
        "for info in pkgutil.iter_modules(maps.__path__):\n"
        "    importlib.import_module(f'tangraph.maps.{info.name}')\n"
        f"for name in {names!r}:\n"
        "    getattr(maps, name)\n"
        "loaded = sorted(m for m in sys.modules if m in ('tangraph.survey', 'tangraph.gridding_surveys'))\n"
        "assert not loaded, loaded\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr


def test_grid_surveys_is_still_found_in_the_maps():
    from tangraph.gridding_surveys import grid_surveys

    assert tangraph.maps.grid_surveys is grid_surveys


def test_modules_are_short_and_so_are_their_functions():
    for path in [*MAPS, *GRIDDING]:
        text = path.read_text()
        assert text.count("\n") <= 500, path.name
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, ast.FunctionDef) and node.name not in LONG:
                assert node.end_lineno - node.lineno < 80, f"{path.name}: {node.name}"
