"""``.. demo-results::``: the figures and the table of ``tangraph demo --quick``, made at build time.

When the build starts, :func:`tangraph.demo.run_demo` runs once (quick mode; the map and seed
are the config values ``demo_results_map`` and ``demo_results_seed``, by default the demo's own
``merimbula`` and 7) into ``docs/generated/demo/`` (git-ignored); the directive shows its track figure, its error
figure and its table, so the landing page shows what the code does today. The run is reused
while nothing it depends on has changed (the ``tangraph`` sources, the scenarios and the map
catalogue: a hash of them is kept beside the report).

``TANGRAPH_DOCS_DEMO=0`` skips the run (for quick builds while writing); the directive then says
that the demo was not run in this build.
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

REPO = Path(__file__).resolve().parents[2]
SOURCES = ("tangraph", "experiments/scenarios", "maps")
SUFFIXES = {".py", ".toml", ".nc", ".npz", ".tif", ".xyz", ".grd"}


def _fingerprint(map_name: str, seed: int) -> str:
    digest = hashlib.sha256(f"map={map_name};seed={seed};quick".encode())
    for folder in SOURCES:
        for path in sorted((REPO / folder).rglob("*")):
            if path.is_file() and path.suffix in SUFFIXES and "__pycache__" not in path.parts:
                digest.update(str(path.relative_to(REPO)).encode())
                digest.update(path.read_bytes())
    return digest.hexdigest()


def _out(app: Sphinx) -> Path:
    return Path(app.srcdir) / "generated" / "demo"


def run_demo_once(app: Sphinx) -> None:
    """Run the quick demo unless its last run is still current."""
    if os.environ.get("TANGRAPH_DOCS_DEMO", "1") == "0":
        return
    from sphinx.util import logging as sphinx_logging

    log = sphinx_logging.getLogger(__name__)
    seed, map_name = app.config.demo_results_seed, app.config.demo_results_map
    out = _out(app)
    stamp = out / "fingerprint.txt"
    want = _fingerprint(map_name, seed)
    if stamp.is_file() and stamp.read_text() == want and (out / "results.json").is_file():
        log.info("demo-results: reusing %s", out)
        return
    from tangraph.demo import run_demo

    out.parent.mkdir(parents=True, exist_ok=True)
    started = time.perf_counter()
    run_demo(out, map_name=map_name, seed=seed, quick=True, force=True, progress=False)
    stamp.write_text(want)
    log.info("demo-results: ran tangraph demo --quick --map %s --seed %d in %.0f s", map_name, seed,
             time.perf_counter() - started)


def _table(rows: list[dict]) -> list[str]:
    def number(value, digits=2):
        try:
            v = float(value)
        except (TypeError, ValueError):
            return str(value)
        if v != v:
            return "--"
        return f"{v:.{digits}f}" if abs(v) < 1e4 else f"{v:.1e}"

    lines = [
        ".. list-table::",
        "   :header-rows: 1",
        "   :class: study-table",
        "",
        "   * - method",
        "     - RMSE (m)",
        "     - final error (m)",
        "     - max error (m)",
        "     - ANEES",
        "     - ms per ping",
        "     - fixes used / refused",
    ]
    for r in rows:
        lines += [
            f"   * - {r['method']}",
            f"     - {number(r['rmse'])}",
            f"     - {number(r['final_error'])}",
            f"     - {number(r['max_error'])}",
            f"     - {number(r['anees'])}",
            f"     - {number(r['ms_per_step'])}",
            f"     - {r.get('fixes') or '--'}",
        ]
    return [*lines, ""]


class DemoResults(SphinxDirective):
    """The quick demo's figures (``:figures: tracks errors fix``) and, with ``:table:``, its table."""

    has_content = False
    option_spec = {"figures": directives.unchanged, "table": directives.flag, "width": directives.unchanged}

    def run(self) -> list[nodes.Node]:
        out = _out(self.env.app)
        if os.environ.get("TANGRAPH_DOCS_DEMO", "1") == "0":
            para = nodes.paragraph(text="(The demo was not run in this build: TANGRAPH_DOCS_DEMO=0.)")
            return [para]
        results = out / "results.json"
        if not results.is_file():
            raise self.error(f"demo-results: {results} is missing; the demo did not run")
        self.env.note_dependency(str(results))
        docdir = Path(self.env.doc2path(self.env.docname)).parent
        width = self.options.get("width", "100%")
        lines: list[str] = []
        for name in (self.options.get("figures") or "tracks").split():
            path = out / f"{name}.png"
            if not path.is_file():
                raise self.error(f"demo-results: the demo wrote no {path.name}")
            rel = Path(os.path.relpath(path, docdir)).as_posix()
            lines += [f".. image:: {rel}", f"   :width: {width}", f"   :alt: demo {name}", ""]
        if "table" in self.options:
            lines += _table(json.loads(results.read_text()))
        container = nodes.container()
        self.state.nested_parse(StringList(lines, source=str(results)), 0, container)
        return container.children


def setup(app: Sphinx) -> dict:
    app.add_config_value("demo_results_seed", 7, "env")
    app.add_config_value("demo_results_map", "merimbula", "env")
    app.add_directive("demo-results", DemoResults)
    app.connect("builder-inited", run_demo_once)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
