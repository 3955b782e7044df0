"""``rocketroll COMMAND --help`` at once: each command's help, kept with the package.

A command's options are its settings dataclass's fields, and the modules that
define them import numpy, scipy, numba, torch and gymnasium: a second or more
before a parser exists.  ``help.json`` holds what those parsers are made of
(:meth:`rocketroll_common.settings.Command.help_tree`: descriptions, each
option's flags, metavar, choices and help; no parsing functions), so that
``rocketroll COMMAND --help`` rebuilds the same argparse parser from the
standard library alone and prints what the full one would, at the terminal's
width.

The file records a digest of the package's sources (:func:`source_digest`);
when they have changed since it was written -- an edited checkout -- the help
comes from the command's own module as before, only slower; so it does while a
plugin is installed or named (:mod:`rocketroll_common.plugins`: its entries
are in the help) and with ``ROCKETROLL_HELP_FROM_SOURCE`` set.  Write it again
with ``make help`` (:func:`rocketroll.cli.write_help`) after changing any source:
a test checks that it is current and matches every command's own parser.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

__all__ = ["CACHE", "PACKAGES", "cached_help", "markdown_reference", "source_digest", "write"]

ROOT = Path(__file__).resolve().parent.parent
#: The packages whose sources the commands' help is made from.
PACKAGES = (
    "rocketroll",
    "rocketroll_common",
    "rocketroll_physics",
    "identification",
    "disturbances",
    "rollenv",
    "agents",
)
#: The help of every command, with the digest of the sources it was made from.
CACHE = Path(__file__).resolve().parent / "help.json"


def source_digest(root: Path = ROOT) -> str:
    """SHA-256 over every ``.py`` file of :data:`PACKAGES` under ``root`` (relative path and
    content, in a fixed order): what the commands' help is made of."""
    digest = hashlib.sha256()
    for package in PACKAGES:
        folder = root / package
        for path in sorted(folder.rglob("*")):
            if path.suffix == ".py" and "__pycache__" not in path.parts:
                digest.update(path.relative_to(root).as_posix().encode())
                digest.update(b"\0")
                digest.update(path.read_bytes())
                digest.update(b"\0")
    return digest.hexdigest()


def _parser(
    tree: dict[str, Any], prog: str
) -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    """The parser ``tree`` describes, and its subcommands' parsers by name."""
    parser = argparse.ArgumentParser(
        prog=prog,
        description=tree["description"],
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    return parser, _fill(parser, tree)


def _fill(
    parser: argparse.ArgumentParser, tree: dict[str, Any]
) -> dict[str, argparse.ArgumentParser]:
    children: dict[str, argparse.ArgumentParser] = {}
    subcommands = tree.get("subcommands")
    if subcommands:
        sub = parser.add_subparsers(dest=tree["dest"], required=True, metavar="COMMAND")
        for child in subcommands:
            made = sub.add_parser(
                child["name"],
                help=child["help"],
                description=child["description"],
                formatter_class=argparse.RawDescriptionHelpFormatter,
            )
            _fill(made, child)
            children[child["name"]] = made
            for alias in child.get("aliases", ()):  # former names: parsed, not listed
                former = sub.add_parser(
                    alias,
                    description=child["description"],
                    formatter_class=argparse.RawDescriptionHelpFormatter,
                )
                _fill(former, child)
                children[alias] = former
        return children
    for flags, kwargs in tree.get("arguments", ()):
        kwargs = dict(kwargs)
        if kwargs.get("action") == "boolean_optional":
            kwargs["action"] = argparse.BooleanOptionalAction
        parser.add_argument(*flags, **kwargs)
    return children


def cached_help(command: str, argv: Sequence[str], prog: str) -> str | None:
    """The help ``rocketroll COMMAND ARGV`` prints, when ``argv`` asks for nothing else
    (``--help``, or a subcommand and ``--help``) and :data:`CACHE` is current; else None
    (the command's own parser answers)."""
    if not 1 <= len(argv) <= 2 or argv[-1] not in ("-h", "--help"):
        return None
    if os.environ.get("ROCKETROLL_HELP_FROM_SOURCE"):  # benchmarks/cli_startup.py compares
        return None
    from rocketroll_common.plugins import plugin_modules

    if plugin_modules():  # a plugin's controllers and methods are in the help
        return None
    try:
        cache = json.loads(CACHE.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    tree = cache.get("commands", {}).get(command)
    if tree is None or cache.get("digest") != source_digest():
        return None
    parser, children = _parser(tree, prog)
    if len(argv) == 1:
        return parser.format_help()
    child = children.get(argv[0])
    return None if child is None else child.format_help()


def write(trees: dict[str, dict[str, Any]], path: Path = CACHE) -> None:
    """Write :data:`CACHE`: every command's help tree
    (:meth:`rocketroll_common.settings.Command.help_tree`) with the sources' digest
    (``make help`` calls :func:`rocketroll.cli.write_help`)."""
    cache = {"digest": source_digest(), "commands": trees}
    text = json.dumps(cache, indent=1, ensure_ascii=False, sort_keys=True) + "\n"
    tmp = path.with_suffix(".json.tmp")
    tmp.write_text(text, encoding="utf-8")
    tmp.replace(path)


def markdown_reference(trees: dict[str, dict[str, Any]], summaries: dict[str, str]) -> str:
    """The command-line reference as Markdown: each command's ``--help`` (and each
    subcommand's), as the terminal prints it at 96 columns, from the help trees the settings
    dataclasses make (:meth:`rocketroll_common.settings.Command.help_tree`); ``summaries``
    are the commands' one-line summaries (``rocketroll --help``).  The documentation site's
    command-line page."""
    before = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "96"  # argparse wraps at the terminal's width
    try:
        out: list[str] = []
        for name, tree in trees.items():
            parser, children = _parser(tree, f"rocketroll {name}")
            out += [f"## rocketroll {name}", "", summaries[name] + ".", ""]
            out += ["```text", parser.format_help().rstrip(), "```", ""]
            former = {a for c in tree.get("subcommands", ()) for a in c.get("aliases", ())}
            for sub, child in children.items():
                if sub in former:  # a renamed command's old name: not documented
                    continue
                out += [f"### rocketroll {name} {sub}", ""]
                out += ["```text", child.format_help().rstrip(), "```", ""]
        return "\n".join(out)
    finally:
        if before is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = before
