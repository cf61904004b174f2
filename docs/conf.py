"""Sphinx configuration of the tangraph documentation.

Build (warnings are errors)::

    MPLBACKEND=Agg .venv/bin/python -m sphinx -W --keep-going -b html docs docs/_build/html
"""

import os
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
os.environ.setdefault("MPLBACKEND", "Agg")

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE / "_ext"))

import tangraph  # noqa: E402

# -- project ---------------------------------------------------------------------------------
project = "tangraph"
author = "the tangraph developers"
copyright = "the tangraph developers"
release = tangraph.__version__
version = ".".join(release.split(".")[:2])

# -- general ---------------------------------------------------------------------------------
extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_gallery.gen_gallery",
    "cliref",
    "catalogue_table",
    "study_readme",
    "demo_results",
]
exclude_patterns = ["_build", "tutorials_src", "**.ipynb_checkpoints"]
templates_path = ["_templates"]
default_role = "py:obj"  # `name` in docstrings links to the Python object when it can

# -- autodoc / autosummary / numpydoc --------------------------------------------------------
autosummary_generate = True  # stubs into docs/generated/ (git-ignored), from api.rst
autodoc_default_options = {"members": True, "member-order": "bysource"}
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_validation_checks: set[str] = set()  # no style validation (ruff and review do that)
numpydoc_xref_param_type = False

# -- sphinx-gallery ---------------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": "tutorials_src",
    "gallery_dirs": "tutorials",
    # every plot_*.py tutorial is executed at build time; TANGRAPH_DOCS_TUTORIALS (a regex, say
    # "plot_07") executes only some, to check a tutorial without waiting for the others
    "filename_pattern": os.environ.get("TANGRAPH_DOCS_TUTORIALS", r"/plot_"),
    "within_subsection_order": "FileNameSortKey",
    "image_scrapers": ("matplotlib",),
    "matplotlib_animations": False,
    "remove_config_comments": True,
    "download_all_examples": False,
    "show_memory": False,
    "reset_modules": ("matplotlib",),
    "min_reported_time": 1,
}

# -- HTML ------------------------------------------------------------------------------------
html_theme = "alabaster"
html_title = f"tangraph {release}"
html_theme_options = {
    "description": "Terrain-aided navigation of AUVs on bathymetry maps",
    "fixed_sidebar": True,
    "show_relbars": True,
    "page_width": "1100px",
}
html_static_path = ["_static"]
html_css_files = ["tangraph.css"]
