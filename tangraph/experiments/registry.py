"""Studies in ``experiments/<name>/run.py``, found and run by name (``tangraph experiment NAME``).

A study's ``run.py`` defines ``main(argv: list[str] | None) -> int``; its per-run function must
be defined at the top level of that file. The file is imported under a private module name and
registered with cloudpickle by value, so Dask worker processes receive its functions without
needing ``experiments/`` on their import path.
"""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

from tangraph.errors import TangraphError

__all__ = ["experiments_path", "list_experiments", "load_experiment", "run_experiment"]


def experiments_path() -> Path:
    """The folder of the studies (the repository's ``experiments/``, or the wheel's copy)."""
    here = Path(__file__).resolve().parent
    for folder in (here.parent / "_experiments", here.parents[1] / "experiments"):
        if folder.is_dir():
            return folder
    raise TangraphError("the experiments folder is missing")


def list_experiments() -> list[str]:
    """Names of the studies (folders with a ``run.py``)."""
    return sorted(p.parent.name for p in experiments_path().glob("*/run.py"))


def load_experiment(name: str) -> ModuleType:
    """Import ``experiments/NAME/run.py`` as a module whose functions can travel to workers."""
    path = experiments_path() / name / "run.py"
    if not path.is_file():
        raise TangraphError(f"no experiment named {name!r}; known: {', '.join(list_experiments()) or 'none'}")
    module_name = f"tangraph_experiment_{name}"
    if module_name in sys.modules:
        return sys.modules[module_name]
    spec = importlib.util.spec_from_file_location(module_name, path)
    module = importlib.util.module_from_spec(spec)  # type: ignore[arg-type]
    sys.modules[module_name] = module
    spec.loader.exec_module(module)  # type: ignore[union-attr]
    import cloudpickle

    cloudpickle.register_pickle_by_value(module)
    if not callable(getattr(module, "main", None)):
        raise TangraphError(f"{path} defines no main(argv) function")
    return module


def run_experiment(name: str, argv: Sequence[str] = ()) -> int:
    """Run a study with its own command-line arguments; returns its exit status."""
    return int(load_experiment(name).main(list(argv)) or 0)
