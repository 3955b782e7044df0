"""The size of the code, package by package, and what is too long in it.

Lines of code are the lines that hold a token of the program: blank lines,
comments and docstrings (a string standing alone as a module's, class's or
function's first statement) are not counted.  Per package (and for
``benchmarks`` and ``tests`` apart) it prints the modules, the lines of code
and the share of the distribution's; then every module over ``--module-limit``
lines of code and every function over ``--function-limit`` lines (its whole
body as written, decorators included), numba kernels marked, longest first.

With ``--json PATH`` the same figures are written for a later comparison (a
restructuring's "before" and "after").

Run from the repository root::

    .venv/bin/python benchmarks/code_size.py [--json runs/code-size.json]
"""

from __future__ import annotations

import argparse
import ast
import io
import json
import sys
import tokenize
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from _records import emit

from rocketroll.help import PACKAGES

REPO = Path(__file__).resolve().parent.parent
OTHERS = ("benchmarks", "tests")
SKIPPED = {tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT}


@dataclass(frozen=True)
class Function:
    """One function: where it is, its length in lines, and whether numba compiles it."""

    where: str
    lines: int
    kernel: bool


def _docstring_lines(tree: ast.AST) -> set[int]:
    """The lines of every docstring in ``tree``."""
    lines: set[int] = set()
    for node in ast.walk(tree):
        if not isinstance(node, ast.Module | ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        first = node.body[0] if node.body else None
        value = first.value if isinstance(first, ast.Expr) else None
        if first is not None and isinstance(value, ast.Constant) and isinstance(value.value, str):
            lines.update(range(first.lineno, (first.end_lineno or first.lineno) + 1))
    return lines


def code_lines(source: str, tree: ast.AST) -> int:
    """Lines of ``source`` that hold a token of the program (not a comment or docstring)."""
    docstrings = _docstring_lines(tree)
    lines: set[int] = set()
    for token in tokenize.generate_tokens(io.StringIO(source).readline):
        if token.type in SKIPPED or token.type == tokenize.ENDMARKER:
            continue
        for line in range(token.start[0], token.end[0] + 1):
            if line not in docstrings:
                lines.add(line)
    return len(lines)


def _is_kernel(node: ast.FunctionDef | ast.AsyncFunctionDef, compiled: set[str]) -> bool:
    """Decorated by numba, or compiled by name (``numba.njit(...)(function)``)."""
    decorated = any(
        "numba" in ast.unparse(d) or "njit" in ast.unparse(d) for d in node.decorator_list
    )
    return decorated or node.name in compiled


def _compiled_by_name(tree: ast.AST) -> set[str]:
    """The functions a module hands to numba by name: ``njit(...)(name)``."""
    return {
        node.args[0].id
        for node in ast.walk(tree)
        if isinstance(node, ast.Call)
        and "njit" in ast.unparse(node.func)
        and node.args
        and isinstance(node.args[0], ast.Name)
    }


def functions(tree: ast.AST, module: str) -> list[Function]:
    """Every function of ``tree`` with its length (first decorator to last line)."""
    found = []
    compiled = _compiled_by_name(tree)
    for node in ast.walk(tree):
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
            length = (node.end_lineno or node.lineno) - first + 1
            kernel = _is_kernel(node, compiled)
            found.append(Function(f"{module}:{node.lineno} {node.name}", length, kernel))
    return found


def measure() -> tuple[dict[str, dict[str, int]], dict[str, int], list[Function]]:
    """Lines of code per package and per module, and every function's length."""
    packages: dict[str, dict[str, int]] = {}
    modules: dict[str, int] = {}
    every: list[Function] = []
    for package in (*PACKAGES, *OTHERS):
        count = lines = 0
        for path in sorted((REPO / package).rglob("*.py")):
            name = path.relative_to(REPO).as_posix()
            source = path.read_text(encoding="utf-8")
            tree = ast.parse(source)
            size = code_lines(source, tree)
            modules[name] = size
            every += functions(tree, name)
            count, lines = count + 1, lines + size
        packages[package] = {"modules": count, "lines": lines}
    return packages, modules, every


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--module-limit", type=int, default=800, help="lines of code")
    parser.add_argument("--function-limit", type=int, default=120, help="lines, as written")
    parser.add_argument("--json", type=Path, help="also write the figures here (a new file)")
    args = parser.parse_args(argv)
    if args.module_limit < 1 or args.function_limit < 1:
        print("code_size.py: error: the limits must be at least 1", file=sys.stderr)
        return 2
    if args.json is not None and args.json.exists():
        print(f"code_size.py: error: --json {args.json}: exists", file=sys.stderr)
        return 2
    packages, modules, every = measure()
    shipped = sum(packages[p]["lines"] for p in PACKAGES)
    print(f"{'package':20s} {'modules':>8s} {'lines of code':>14s} {'share':>7s}")
    for package, size in packages.items():
        share = f"{100 * size['lines'] / shipped:6.1f}%" if package in PACKAGES else "      -"
        print(f"{package:20s} {size['modules']:8d} {size['lines']:14d} {share}")
    print(f"{'distribution':20s} {'':8s} {shipped:14d}")
    for package, size in packages.items():
        emit(f"{package}: lines of code", size["lines"], "lines", note=f"{size['modules']} modules")
    emit("distribution: lines of code", shipped, "lines")
    long_modules = sorted(
        ((n, s) for n, s in modules.items() if s > args.module_limit), key=lambda x: -x[1]
    )
    print(f"\nmodules over {args.module_limit} lines of code: {len(long_modules)}")
    for name, lines in long_modules:
        print(f"  {lines:6d}  {name}")
    long_functions = sorted(
        (f for f in every if f.lines > args.function_limit), key=lambda f: -f.lines
    )
    kernels = sum(f.kernel for f in long_functions)
    emit(f"modules over {args.module_limit} lines of code", len(long_modules), "", at_most=0)
    emit(
        f"functions over {args.function_limit} lines, numba kernels aside",
        len(long_functions) - kernels,
        "",
        note=", ".join(f.where for f in long_functions if not f.kernel),
    )
    print(
        f"\nfunctions over {args.function_limit} lines: {len(long_functions)} "
        f"({kernels} numba kernels)"
    )
    for f in long_functions:
        print(f"  {f.lines:6d}  {f.where}{'  (numba kernel)' if f.kernel else ''}")
    if args.json is not None:
        record = {
            "packages": packages,
            "modules": modules,
            "functions": [vars(f) for f in every],
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        print(f"\nwrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
