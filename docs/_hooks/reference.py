"""MkDocs hooks of the reference pages.

* The command-line reference page, generated at build time from the settings dataclasses
  that make every command's ``--help`` (nothing of it is written by hand).
* The docstrings' Sphinx roles (``:func:`x` ``, ``:class:`x` ``, ...), which
  mkdocstrings renders as they are written, shown as the code they name (``~`` too:
  Sphinx's "last part only" mark).
"""

from __future__ import annotations

import re
from typing import Any

#: A Sphinx role before the code it names, as mkdocstrings renders it.
ROLE = re.compile(r":(?:func|class|data|mod|meth|attr|exc|obj|const):<code>~?")

#: Where the generated reference goes in ``reference/cli.md``.
MARKER = "<!-- the commands -->"


def on_page_markdown(markdown: str, page: Any, **kwargs: Any) -> str:
    if page.file.src_uri != "reference/cli.md":
        return markdown
    from rocketroll.cli import COMMANDS, command
    from rocketroll.help import markdown_reference

    trees = {name: command(name).help_tree() for name in COMMANDS}
    summaries = {name: summary for name, (_, summary) in COMMANDS.items()}
    if MARKER not in markdown:
        raise ValueError(f"reference/cli.md: no {MARKER!r} line to put the commands at")
    return markdown.replace(MARKER, markdown_reference(trees, summaries))


def on_page_content(html: str, page: Any, **kwargs: Any) -> str:
    return ROLE.sub("<code>", html)
