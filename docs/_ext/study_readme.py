"""``.. study-readme:: NAME``: a study's ``experiments/NAME/README.md``, rendered in the page.

The studies keep their results in Markdown next to their code (GitHub shows it there); the docs
show the same file, so the two cannot drift apart. The README is turned into reStructuredText
and inserted where the directive stands, as ``.. include::`` would insert a file. The
Markdown understood is what the READMEs use: ``#`` headings, paragraphs, ``-`` lists (with
indented continuation lines), pipe tables, indented and fenced code blocks, images, inline
code, bold, italics and links. The README's first heading (its title) is dropped unless
``:keep-title:`` is given; the others become sections one level below the page's sections
(``##`` -> ``~``, ``###`` -> ``^``).

Images and files the README links to are given by paths relative to the README; images are
rendered from there (Sphinx copies them into the build).
"""

from __future__ import annotations

import os
import re
from pathlib import Path

from docutils import nodes
from docutils.parsers.rst import directives
from docutils.statemachine import StringList
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

REPO = Path(__file__).resolve().parents[2]
UNDERLINES = {2: "~", 3: "^", 4: '"'}

_CODE = re.compile(r"`([^`]+)`")
_IMAGE = re.compile(r"^!\[([^\]]*)\]\(([^)\s]+)\)\s*$")
_LINK = re.compile(r"\[([^\]]+)\]\(([^)\s]+)\)")
_HEADING = re.compile(r"^(#{1,6})\s+(.*?)\s*#*\s*$")
_BULLET = re.compile(r"^(\s*)([-*+]|\d+[.)])\s+(.*)$")
_RULE = re.compile(r"^\s*\|?\s*:?-{3,}:?\s*(\|\s*:?-{3,}:?\s*)*\|?\s*$")


def _escape(text: str) -> str:
    """Plain Markdown text whose characters RST would read as markup, escaped."""
    text = text.replace("\\", "\\\\")
    text = re.sub(r"\|", r"\\|", text)
    text = re.sub(r"(?<=\w)_(?=\s|$|[.,;:)])", r"\\_", text)  # word_ would be a reference
    return text


def _wrap(marker: str, body: str, before: str, after: str) -> str:
    """``marker body marker`` with the escapes RST needs when a word character touches it."""
    left = "\\ " if before and (before[-1].isalnum() or before[-1] in "_)") else ""
    right = "\\ " if after and (after[0].isalnum() or after[0] in "_(") else ""
    return f"{left}{marker}{body}{marker}{right}"


def inline(text: str) -> str:
    """Markdown inline markup (code, links, bold, italics) as RST."""
    out: list[str] = []
    pos = 0
    pieces: list[tuple[str, str]] = []  # (kind, text): kind "text" or "rst"
    for match in _CODE.finditer(text):
        pieces.append(("text", text[pos : match.start()]))
        pieces.append(("code", match.group(1)))
        pos = match.end()
    pieces.append(("text", text[pos:]))
    for index, (kind, piece) in enumerate(pieces):
        before = "".join(out)
        after = pieces[index + 1][1] if index + 1 < len(pieces) else ""
        if kind == "code":
            out.append(_wrap("``", piece, before, after))
            continue
        rendered = []
        last = 0
        for match in _LINK.finditer(piece):
            rendered.append(_escape(piece[last : match.start()]))
            label, target = match.group(1), match.group(2)
            if re.match(r"^[a-z]+://", target):
                rendered.append(f"`{_escape(label)} <{target}>`__")
            else:  # a file of the repository: name it, as the link cannot follow it into the docs
                rendered.append(f"{_escape(label)} (``{target}``)")
            last = match.end()
        rendered.append(_escape(piece[last:]))
        out.append("".join(rendered))
    return "".join(out)


def _table(rows: list[str]) -> list[str]:
    cells = [[c.strip() for c in row.strip().strip("|").split("|")] for row in rows]
    header, body = cells[0], [r for r in cells[1:] if not all(re.fullmatch(r":?-{3,}:?", c) for c in r)]
    n = len(header)
    lines = [".. list-table::", "   :header-rows: 1", "   :class: study-table", ""]
    for row in [header, *body]:
        row = (row + [""] * n)[:n]
        for k, cell in enumerate(row):
            lines.append(f"   {'*' if k == 0 else ' '} - {inline(cell) or '..'}".replace("- ..", "-"))
    return [*lines, ""]


def markdown_to_rst(text: str, readme: Path, docdir: Path, *, keep_title: bool = False) -> list[str]:
    """The RST lines of a Markdown README (paths of images made relative to ``docdir``)."""
    lines = text.splitlines()
    out: list[str] = []
    i = 0
    titled = keep_title

    def para_end(j: int) -> bool:
        line = lines[j]
        return (
            not line.strip()
            or bool(_HEADING.match(line))
            or line.lstrip().startswith("|")
            or line.startswith("```")
            or bool(_IMAGE.match(line.strip()))
        )

    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if not stripped:
            i += 1
            continue
        if stripped.startswith("```"):  # fenced code
            language = stripped[3:].strip() or "text"
            body = []
            i += 1
            while i < len(lines) and not lines[i].strip().startswith("```"):
                body.append(lines[i])
                i += 1
            i += 1
            out += [f".. code-block:: {language}", "", *("   " + b for b in body), ""]
            continue
        if line.startswith("    ") or line.startswith("\t"):  # indented code
            body = []
            while i < len(lines) and (lines[i].startswith("    ") or not lines[i].strip()):
                body.append(lines[i][4:] if lines[i].startswith("    ") else "")
                i += 1
            while body and not body[-1]:
                body.pop()
            out += [".. code-block:: text", "", *("   " + b for b in body), ""]
            continue
        heading = _HEADING.match(line)
        if heading:
            level, title = len(heading.group(1)), inline(heading.group(2))
            i += 1
            if level == 1 and not titled:
                titled = True
                continue
            char = "=" if level == 1 else UNDERLINES.get(level, '"')
            out += [title, char * max(len(title), 3), ""]
            continue
        image = _IMAGE.match(stripped)
        if image:
            target = Path(os.path.relpath(readme.parent / image.group(2), docdir)).as_posix()
            out += [f".. image:: {target}", f"   :alt: {image.group(1) or target}", ""]
            i += 1
            continue
        if stripped.startswith("|"):
            rows = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                rows.append(lines[i])
                i += 1
            out += _table(rows)
            continue
        bullet = _BULLET.match(line)
        if bullet:
            while i < len(lines):
                bullet = _BULLET.match(lines[i])
                if not bullet:
                    break
                indent = len(bullet.group(1))
                marker = "-" if bullet.group(2) in "-*+" else "#."
                item = [bullet.group(3)]
                i += 1
                while i < len(lines) and lines[i].strip() and not _BULLET.match(lines[i]):
                    if len(lines[i]) - len(lines[i].lstrip()) <= indent and para_end(i):
                        break
                    item.append(lines[i].strip())
                    i += 1
                pad = " " * (indent // 2 * 2)
                if pad and (not out or out[-1]):
                    out.append("")
                out.append(f"{pad}{marker} {inline(' '.join(item))}")
                if i < len(lines) and not lines[i].strip():
                    j = i
                    while j < len(lines) and not lines[j].strip():
                        j += 1
                    if j < len(lines) and _BULLET.match(lines[j]):
                        i = j
            out.append("")
            continue
        paragraph = [stripped]
        i += 1
        while i < len(lines) and not para_end(i) and not _BULLET.match(lines[i]):
            paragraph.append(lines[i].strip())
            i += 1
        out += [inline(" ".join(paragraph)), ""]
    return out


class StudyReadme(SphinxDirective):
    """Insert ``experiments/NAME/README.md`` as reStructuredText."""

    required_arguments = 1
    has_content = False
    option_spec = {"keep-title": directives.flag}

    def run(self) -> list[nodes.Node]:
        readme = REPO / "experiments" / self.arguments[0] / "README.md"
        if not readme.is_file():
            raise self.error(f"study-readme: {readme} does not exist")
        self.env.note_dependency(str(readme))
        docdir = Path(self.env.doc2path(self.env.docname)).parent
        rst = markdown_to_rst(
            readme.read_text(encoding="utf-8"), readme, docdir, keep_title="keep-title" in self.options
        )
        self.state_machine.insert_input(StringList(rst, source=str(readme)), str(readme))
        return []


def setup(app: Sphinx) -> dict:
    app.add_directive("study-readme", StudyReadme)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
