"""``.. catalogue-table::``: the shipped map catalogue as a table, read from catalogue.toml.

Read through :func:`tangraph.maps.catalogue`, so the table is the catalogue the package sees.
"""

from __future__ import annotations

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective


def _cell(text: str, *, markup: bool = False) -> str:
    """One line of table text; plain text has its RST markup characters escaped."""
    text = " ".join(str(text).split())
    if not markup:
        for char in "\\`*_|":
            text = text.replace(char, "\\" + char)
    return text or "--"


class CatalogueTable(SphinxDirective):
    """A list-table with one row per catalogue map."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        from tangraph.maps import catalogue, catalogue_path

        self.env.note_dependency(str(catalogue_path() / "catalogue.toml"))
        lines = [
            ".. list-table::",
            "   :header-rows: 1",
            "   :widths: 12 38 22 14 14",
            "",
            "   * - name",
            "     - title",
            "     - data",
            "     - licence",
            "     - source",
        ]
        for entry in catalogue().values():
            if entry.generator is not None:
                data = f"``{entry.generator}`` (seed {entry.seed})"
            else:
                options = ", ".join(f"``{k}={v!r}``" for k, v in entry.read.items())
                data = f"``{entry.file}``" + (f", read with {options}" if options else "")
            if entry.shallowest is not None:
                data += f"; shallowest cell at {entry.shallowest:g} m"
            lines += [
                f"   * - ``{entry.name}``",
                f"     - {_cell(entry.title)}",
                f"     - {_cell(data, markup=True)}",
                f"     - {_cell(entry.licence)}",
                f"     - {_cell(entry.source)}",
            ]
        container = nodes.container()
        self.state.nested_parse(StringList(lines, source="catalogue.toml"), 0, container)
        return container.children


def setup(app: Sphinx) -> dict:
    app.add_directive("catalogue-table", CatalogueTable)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
