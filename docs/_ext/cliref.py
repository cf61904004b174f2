"""``.. cliref:: module:function``: the help of an argparse command and all its subcommands.

The function is called with no arguments and must return an ``argparse.ArgumentParser``. Each
(sub)command becomes a section titled by its ``prog`` (``tangraph maps info``), holding its
``format_help()`` as a literal block, so the reference cannot drift from the parser.
"""

from __future__ import annotations

import argparse
import importlib
import os
from collections.abc import Iterator

from docutils import nodes
from sphinx.application import Sphinx
from sphinx.util.docutils import SphinxDirective

HELP_WIDTH = "78"  # argparse wraps to $COLUMNS; fix it so that the build is reproducible


def _commands(parser: argparse.ArgumentParser) -> Iterator[argparse.ArgumentParser]:
    """The parser, then its subcommands depth-first, in the order they were added."""
    yield parser
    for action in parser._actions:  # argparse keeps subparsers only here
        if isinstance(action, argparse._SubParsersAction):
            for sub in dict.fromkeys(action.choices.values()):  # aliases share a parser
                yield from _commands(sub)


def _help(parser: argparse.ArgumentParser) -> str:
    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_WIDTH
    try:
        return parser.format_help()
    finally:
        if saved is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = saved


class CliRef(SphinxDirective):
    """Render every (sub)command's help of the parser built by ``module:function``."""

    required_arguments = 1
    has_content = False

    def run(self) -> list[nodes.Node]:
        module, _, function = self.arguments[0].partition(":")
        parser = getattr(importlib.import_module(module), function)()
        self.env.note_dependency(importlib.import_module(module).__file__)
        sections = []
        for command in _commands(parser):
            section = nodes.section(ids=[nodes.make_id(command.prog)], names=[command.prog])
            section += nodes.title(text=command.prog)
            text = _help(command)
            block = nodes.literal_block(text, text, language="text")
            section += block
            self.state.document.note_implicit_target(section)
            sections.append(section)
        return sections


def setup(app: Sphinx) -> dict:
    app.add_directive("cliref", CliRef)
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
