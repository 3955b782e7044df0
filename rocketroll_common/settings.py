"""Settings dataclasses, their checks, and the command lines made from them.

A settings dataclass declares each field once, with :func:`setting`: its type
(the annotation), default, help, choices, physical bounds, flag.  From that
one declaration come

* the checks (:func:`check`, called from the dataclass's ``__post_init__``):
  types, choices and bounds, each failure a
  :class:`~rocketroll_common.errors.SettingError` naming the field;
* the command-line options (:func:`add_arguments`) and the instance from the
  parsed options (:func:`from_namespace`), errors named by flag;
* the words that reproduce an instance (:func:`to_argv`), which
  :func:`parse` reads back: a recorded ``# command:`` line and the command a
  run echoes are made by the code that parses them.

This is CleanRL's ``args = tyro.cli(Args)`` on the standard library's
``argparse``, so that ``rocketroll --help`` stays fast.  :class:`Command`
and :func:`run_command` turn a dataclass and a function into a command with
one-line errors (exit 2), a one-line "interrupted" on Ctrl-C (exit 130), and
every output checked before the work starts.

Examples
--------
>>> from dataclasses import dataclass
>>> @dataclass(frozen=True)
... class Args:
...     seed: int = setting(0, "random seed", ge=0, always=True)
...     sd: float = setting(9.8, "standard deviation, °", ge=0, le=45)
...     fast: bool = setting(False, "skip the slow part")
...     def __post_init__(self) -> None:
...         check(self)
>>> parse(Args, ["--sd", "2.5", "--fast"])
Args(seed=0, sd=2.5, fast=True)
>>> to_argv(Args(sd=2.5))
['--seed', '0', '--sd', '2.5']
>>> Args(sd=100.0)
Traceback (most recent call last):
...
rocketroll_common.errors.SettingError: sd: must be in [0, 45], got 100.0
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import math
import numbers
import os
import re
import signal
import sys
import threading
import types
from collections.abc import Callable, Iterator, Sequence
from dataclasses import MISSING, dataclass, field
from pathlib import Path
from typing import Any, Literal, Union, get_args, get_origin, get_type_hints

from rocketroll_common.errors import Interrupted, RocketrollError, SettingError, UsageError

__all__ = [
    "ArgumentParser",
    "Command",
    "add_arguments",
    "check",
    "check_order",
    "flags",
    "from_namespace",
    "guarded",
    "interrupts_held",
    "make_parser",
    "parse",
    "parse_key_value",
    "renamed_note",
    "run_command",
    "setting",
    "to_argv",
]

_KEY = "rocketroll.setting"


@dataclass(frozen=True)
class _Spec:
    help: str | Callable[[], str]
    flag: str | None
    choices: tuple[Any, ...] | Callable[[], Sequence[Any]] | None
    ge: float | None
    gt: float | None
    le: float | None
    lt: float | None
    unit: str
    positional: bool
    metavar: str | None
    parse: Callable[[str], Any] | None
    format: Callable[[Any], str] | None
    output: str | None
    kind: str | None
    files: Sequence[str] | Callable[[Any], Sequence[str]] | None
    input: bool
    flatten: bool
    cli: bool
    always: bool


def setting(
    default: Any = MISSING,
    help: str | Callable[[], str] = "",
    *,
    default_factory: Callable[[], Any] | Any = MISSING,
    flag: str | None = None,
    choices: Sequence[Any] | Callable[[], Sequence[Any]] | None = None,
    ge: float | None = None,
    gt: float | None = None,
    le: float | None = None,
    lt: float | None = None,
    unit: str = "",
    positional: bool = False,
    metavar: str | None = None,
    parse: Callable[[str], Any] | None = None,
    format: Callable[[Any], str] | None = None,
    output: Literal["file", "folder"] | None = None,
    kind: str | None = None,
    files: Sequence[str] | Callable[[Any], Sequence[str]] | None = None,
    input: bool = False,
    flatten: bool = False,
    cli: bool = True,
    always: bool = False,
) -> Any:
    """A dataclass field with everything its checks and its option need.

    Parameters
    ----------
    default, default_factory
        As for :func:`dataclasses.field`; neither makes the option required.
    help : str or callable
        One line for ``--help``; a function is called when the parser is made
        (help that lists a registry, which may grow after import).
    flag : str, optional
        The option (``--min-step``); default ``--`` plus the field name with
        dashes.
    choices : sequence or callable, optional
        Allowed values (a ``Literal`` annotation gives them too); a function
        is called whenever they are needed (the names of a registry).
    ge, gt, le, lt : float, optional
        Bounds (``>=``, ``>``, ``<=``, ``<``), for numbers and for each item
        of a tuple of numbers.  Floats must also be finite.
    unit : str
        Shown after the bounds in messages.
    positional : bool
        A positional argument instead of an option.
    metavar : str, optional
        The value's name in ``--help``.
    parse, format : callable, optional
        Text to value and value to text, for types the module does not know.
    output : {"file", "folder"}, optional
        The field names an output; :func:`run_command` checks it can be
        written before the command works, and that writing it destroys
        nothing (:func:`rocketroll_common.files.check_output`).
    kind : str, optional
        What the file holds (a key of :data:`rocketroll_common.files.KINDS`):
        for an output, what the command writes there (an existing file of
        another kind is refused); for an input, what it must hold if it exists.
    files : sequence of str, or callable, optional
        For a folder output, the files the command writes there (paths in the
        folder) as far as they are known before the work, or a function of
        the arguments that gives them: an existing one that rocketroll did not
        write there (or that changed since) is refused before the work
        (:func:`rocketroll_common.files.check_folder_files`).  Given, the
        command gets ``--force`` (:data:`FORCE_FLAG`) to replace them, and
        must write the folder with ``write_all_atomic(..., folder=...)``,
        which checks every file it writes there again.
    input : bool
        The field names input files (a path, or a list of them; a database
        given as ``scheme://...`` is not a file): no output may be one of
        them.
    flatten : bool
        The field is itself a settings dataclass whose options are added
        here, without a prefix.
    cli : bool
        False: a library setting with no option.
    always : bool
        :func:`to_argv` writes it even at its default (a seed).
    """
    spec = _Spec(
        help=help,
        flag=flag,
        choices=choices if choices is None or callable(choices) else tuple(choices),
        ge=ge,
        gt=gt,
        le=le,
        lt=lt,
        unit=unit,
        positional=positional,
        metavar=metavar,
        parse=parse,
        format=format,
        output=output,
        kind=kind,
        files=files if files is None or callable(files) else tuple(files),
        input=input,
        flatten=flatten,
        cli=cli,
        always=always,
    )
    metadata = {_KEY: spec}
    if default_factory is not MISSING:
        return field(default_factory=default_factory, metadata=metadata)
    return field(default=default, metadata=metadata)


# ----------------------------------------------------------------------------- types
@dataclass(frozen=True)
class _Field:
    name: str
    spec: _Spec
    base: Any  # int, float, str, bool, Path, tuple, list, dict or a dataclass
    item: Any  # the item type of a tuple or list
    optional: bool
    literal: tuple[Any, ...] | None  # the choices of a Literal annotation
    given_default: Any  # MISSING when required or made by a factory
    factory: Any  # the dataclass field's default_factory, or MISSING

    @property
    def default(self) -> Any:
        """The default, made now (a factory may read a registry that has grown)."""
        if self.factory is not MISSING:
            return self.factory()
        return self.given_default

    @property
    def choices(self) -> tuple[Any, ...] | None:
        """Allowed values, read now (a registry may have grown since import)."""
        given = self.spec.choices
        if callable(given):
            return tuple(given())
        return given if given is not None else self.literal

    @property
    def flag(self) -> str:
        return self.spec.flag or "--" + self.name.replace("_", "-")

    @property
    def shown(self) -> str:
        """How the user names it: the flag, a positional's metavar, or (a setting with no
        option) the field's name."""
        if self.spec.positional:
            return self.spec.metavar or self.name.upper()
        if not self.spec.cli:
            return self.name
        return self.flag


_FIELDS: dict[type, tuple[_Field, ...]] = {}


def _fields(cls: type) -> tuple[_Field, ...]:
    """The annotated fields of a settings dataclass (cached per class)."""
    cached = _FIELDS.get(cls)
    if cached is not None:
        return cached
    hints = get_type_hints(cls)
    out = []
    for f in dataclasses.fields(cls):
        spec = f.metadata.get(_KEY)
        if spec is None or not f.init:
            continue
        kind = hints[f.name]
        optional = False
        if get_origin(kind) in (Union, types.UnionType):
            args = [a for a in get_args(kind) if a is not type(None)]
            optional = len(args) < len(get_args(kind))
            kind = args[0] if len(args) == 1 else kind
        literal = None
        if get_origin(kind) is Literal:
            literal = get_args(kind)
            kind = type(literal[0])
        item: Any = None
        origin = get_origin(kind)
        if origin in (tuple, list):
            item = get_args(kind)[0] if get_args(kind) else str
            kind = origin
        elif origin is dict:
            kind = dict
        out.append(
            _Field(f.name, spec, kind, item, optional, literal, f.default, f.default_factory)
        )
    _FIELDS[cls] = tuple(out)
    return _FIELDS[cls]


def _leaves(cls: type) -> list[_Field]:
    """Every field, with flattened settings dataclasses replaced by their own fields."""
    out: list[_Field] = []
    for f in _fields(cls):
        if f.spec.flatten:
            out += _leaves(f.base)
        else:
            out.append(f)
    return out


def flags(cls: type) -> dict[str, str]:
    """Field name -> how the user names it (flag or positional name), flattened."""
    return {f.name: f.shown for f in _leaves(cls)}


# ----------------------------------------------------------------------------- checks
def _bound(x: float | None, integer: bool) -> str:
    if x is None:
        return ""
    return str(int(x)) if integer else f"{x:g}"


def _bounds_text(spec: _Spec, integer: bool = False) -> str:
    low = _bound(spec.ge if spec.gt is None else spec.gt, integer)
    high = _bound(spec.le if spec.lt is None else spec.lt, integer)
    unit = f" {spec.unit}" if spec.unit else ""
    if low and high:
        left = "[" if spec.gt is None else "("
        right = "]" if spec.lt is None else ")"
        return f"must be in {left}{low}, {high}{right}{unit}"
    if low:
        return f"must be {'>=' if spec.gt is None else '>'} {low}{unit}"
    return f"must be {'<=' if spec.lt is None else '<'} {high}{unit}"


def _in_bounds(spec: _Spec, x: float) -> bool:
    return not (
        (spec.ge is not None and not x >= spec.ge)
        or (spec.gt is not None and not x > spec.gt)
        or (spec.le is not None and not x <= spec.le)
        or (spec.lt is not None and not x < spec.lt)
    )


def _check_number(f: _Field, kind: Any, value: Any) -> str | None:
    """What is wrong with one number, or None."""
    if kind is int:
        if isinstance(value, bool) or not isinstance(value, numbers.Integral):
            return f"must be an integer, got {value!r}"
    elif kind is float:
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            return f"must be a number, got {value!r}"
        if not math.isfinite(float(value)):
            return f"must be finite, got {value!r}"
    else:
        return None
    if not _in_bounds(f.spec, float(value)):
        return f"{_bounds_text(f.spec, kind is int)}, got {value!r}"
    return None


def check(obj: Any) -> None:
    """Check every :func:`setting` field of ``obj`` against its declaration.

    Raises
    ------
    SettingError
        Naming the first field that has the wrong type, a value outside its
        choices, or a number outside its bounds.
    """
    for f in _fields(type(obj)):
        value = getattr(obj, f.name)
        if value is None:
            if f.optional:
                continue
            raise SettingError(f.name, "is required")
        choices = f.choices
        if f.base is bool and not isinstance(value, bool):
            raise SettingError(f.name, f"must be True or False, got {value!r}")
        if f.base in (tuple, list):
            try:
                items = tuple(value)
            except TypeError:
                raise SettingError(f.name, f"must be a sequence, got {value!r}") from None
            for item in items:
                if choices is not None and item not in choices:
                    allowed = ", ".join(map(str, choices))
                    raise SettingError(f.name, f"must be one of {allowed}, not {item!r}")
                problem = _check_number(f, f.item, item)
                if problem:
                    raise SettingError(f.name, problem)
            continue
        if choices is not None and value not in choices:
            allowed = ", ".join(map(str, choices))
            raise SettingError(f.name, f"must be one of {allowed}, not {value!r}")
        problem = _check_number(f, f.base, value)
        if problem:
            raise SettingError(f.name, problem)


def check_order(
    field: str, first: float | None, second: float | None, flag: str, unit: str
) -> None:
    """Refuse (:class:`SettingError` naming ``field``) a range whose two ends are both given
    and not in order: ``first`` must be below ``second`` (given as ``flag``)."""
    if first is not None and second is not None and not first < second:
        raise SettingError(field, f"{first:g} {unit} must be below {flag} {second:g} {unit}")


# ----------------------------------------------------------------------------- parsing
class ArgumentParser(argparse.ArgumentParser):
    """``argparse`` that raises :class:`UsageError` instead of printing usage and exiting."""

    def error(self, message: str) -> Any:
        raise UsageError(message)


def parse_key_value(text: str) -> tuple[str, Any]:
    """``KEY=VALUE`` with VALUE read as a bool, int, float or string."""
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    value: Any = raw
    if raw.lower() in ("true", "false"):
        value = raw.lower() == "true"
    else:
        for kind in (int, float):
            try:
                value = kind(raw)
                break
            except ValueError:
                continue
    return key, value


def _number_parser(kind: type) -> Callable[[str], Any]:
    def parse(text: str) -> Any:
        try:
            return kind(text)
        except ValueError:
            word = "an integer" if kind is int else "a number"
            raise argparse.ArgumentTypeError(f"must be {word}, not {text!r}") from None

    return parse


def _tuple_parser(kind: type) -> Callable[[str], tuple[Any, ...]]:
    one = _number_parser(kind) if kind in (int, float) else kind

    def parse(text: str) -> tuple[Any, ...]:
        try:
            return tuple(one(x) for x in text.split(","))
        except argparse.ArgumentTypeError:
            raise argparse.ArgumentTypeError(
                f"must be comma-separated {'numbers' if kind is float else 'values'}, not {text!r}"
            ) from None

    return parse


#: The folder holding rocketroll's packages (a checkout, or site-packages).
_PACKAGES = Path(__file__).resolve().parents[1]


def _help(f: _Field) -> str:
    """The option's help: its text, the range its value must lie in, its default."""
    text = f.spec.help() if callable(f.spec.help) else f.spec.help
    spec = f.spec
    bounded = any(b is not None for b in (spec.ge, spec.gt, spec.le, spec.lt))
    integer = f.base is int or f.item is int
    limits = _bounds_text(spec, integer).removeprefix("must be ") if bounded else ""
    shown = f.default
    if (
        shown is not MISSING
        and shown is not None
        and not (isinstance(shown, bool) or shown in ([], {}, ()))
        and "default" not in text
        and not f.spec.positional
    ):
        if isinstance(shown, Path) and shown.is_absolute() and shown.is_relative_to(_PACKAGES):
            shown = shown.relative_to(_PACKAGES)  # a file of the package, wherever installed
        if f.base is tuple:
            shown = ",".join(map(str, shown))
        elif f.base is list:
            shown = " ".join(map(str, shown))
        unit = f" {f.spec.unit}" if f.spec.unit else ""
        text = f"{text} ({limits + '; ' if limits else ''}default: {shown}{unit})"
    elif limits:
        text = f"{text} ({limits})"
    elif f.spec.unit and f.spec.unit not in text:
        text = f"{text} ({f.spec.unit})"
    return text.replace("%", "%%")


def add_arguments(parser: argparse.ArgumentParser, cls: type) -> None:
    """One option (or positional) per :func:`setting` field of ``cls``, flattened."""
    for flags, kwargs in argument_specs(cls):
        parser.add_argument(*flags, **kwargs)


def argument_specs(cls: type) -> list[tuple[tuple[str, ...], dict[str, Any]]]:
    """The ``parser.add_argument(*flags, **kwargs)`` calls of :func:`add_arguments`."""
    specs: list[tuple[tuple[str, ...], dict[str, Any]]] = []
    seen: set[str] = set()
    for f in _leaves(cls):
        if not f.spec.cli:
            continue
        if f.name in seen:
            raise TypeError(f"{cls.__name__}: field {f.name!r} appears twice when flattened")
        seen.add(f.name)
        kwargs: dict[str, Any] = {"help": _help(f)}
        if f.spec.metavar:
            kwargs["metavar"] = f.spec.metavar
        choices = f.choices
        if choices is not None and f.base is not tuple:  # a tuple's items: check() does it
            kwargs["choices"] = choices
        parse = f.spec.parse
        if f.base is bool:
            if f.default is True:
                kwargs["action"] = argparse.BooleanOptionalAction
                kwargs["default"] = True
            else:
                kwargs["action"] = "store_true"
            specs.append(((f.flag,), {"dest": f.name, **kwargs}))
            continue
        if parse is None:
            if f.base in (int, float):
                parse = _number_parser(f.base)
            elif f.base is tuple:
                parse = _tuple_parser(f.item)
            elif f.base is dict:
                parse = parse_key_value
            elif f.base is list:
                parse = f.item if f.item in (str, Path) else _number_parser(f.item)
            else:
                parse = f.base
        kwargs["type"] = parse
        if f.spec.positional:
            if f.base is list:
                kwargs["nargs"] = "*"
            elif f.default is not MISSING:
                kwargs["nargs"] = "?"
                kwargs["default"] = f.default
            kwargs.setdefault("metavar", f.spec.metavar or f.name)
            specs.append(((f.name,), kwargs))
            continue
        if f.base in (list, dict):
            kwargs["action"] = "append"
            kwargs["default"] = None
        elif f.default is MISSING:
            kwargs["required"] = True
        else:
            kwargs["default"] = f.default
        specs.append(((f.flag,), {"dest": f.name, **kwargs}))
    if _folder_outputs(cls) and "force" not in seen:
        specs.append(((FORCE_FLAG,), {"dest": "force", "help": FORCE_HELP, "action": "store_true"}))
    return specs


#: The option of every command with a folder output whose files are declared
#: (``setting(output="folder", files=...)``): replace what rocketroll did not write there.
FORCE_FLAG = "--force"
FORCE_HELP = (
    "write into the output folder over files rocketroll did not write there (or that were "
    "changed since): they are replaced"
)


def _folder_outputs(cls: type) -> list[_Field]:
    """The folder outputs of ``cls`` (flattened) whose files are declared."""
    return [f for f in _leaves(cls) if f.spec.output == "folder" and f.spec.files is not None]


def _value(f: _Field, ns: argparse.Namespace) -> Any:
    if not f.spec.cli or not hasattr(ns, f.name):
        return f.default
    value = getattr(ns, f.name)
    if f.base is dict:
        return dict(value) if value else dict(f.default)
    if f.base is list:
        return list(value) if value else list(f.default)
    return value


def _build(cls: type, ns: argparse.Namespace) -> Any:
    kwargs: dict[str, Any] = {}
    for f in _fields(cls):
        value = _build(f.base, ns) if f.spec.flatten else _value(f, ns)
        if value is not MISSING:
            kwargs[f.name] = value
    obj = cls(**kwargs)
    check(obj)  # also for a dataclass whose __post_init__ does not
    return obj


def from_namespace(cls: type, ns: argparse.Namespace) -> Any:
    """The instance of ``cls`` the parsed options describe.

    Raises
    ------
    UsageError
        The dataclass refused a value: a :class:`SettingError` is reported
        under the option's flag, another ``ValueError`` as it is.
    """
    try:
        return _build(cls, ns)
    except SettingError as exc:
        shown = flags(cls).get(exc.setting, exc.setting)
        raise UsageError(f"{shown}: {exc.problem}") from None
    except ValueError as exc:
        raise UsageError(str(exc)) from None


def make_parser(cls: type, prog: str, description: str | None = None) -> ArgumentParser:
    """A parser with the options of ``cls``."""
    parser = ArgumentParser(
        prog=prog, description=description, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    add_arguments(parser, cls)
    return parser


def parse(cls: type, argv: Sequence[str], prog: str | None = None) -> Any:
    """``cls`` from command-line words (:class:`UsageError` on any problem)."""
    parser = make_parser(cls, prog or cls.__name__)
    return from_namespace(cls, parser.parse_args(list(argv)))


# ----------------------------------------------------------------------------- writing
def _text(f: _Field, value: Any) -> str:
    if f.spec.format is not None:
        return f.spec.format(value)
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, tuple):
        return ",".join(repr(x) if isinstance(x, float) else str(x) for x in value)
    return str(value)


def to_argv(obj: Any) -> list[str]:
    """The command-line words that :func:`parse` turns back into ``obj``.

    Options at their default are left out (but those declared ``always``);
    floats are written as their shortest exact ``repr``.
    """
    words: list[str] = []
    for f in _fields(type(obj)):
        value = getattr(obj, f.name)
        if f.spec.flatten:
            words += to_argv(value)
            continue
        if not f.spec.cli:
            continue
        if f.spec.positional:
            items = value if f.base is list else [value]
            words += [_text(f, x) for x in items if x is not None]
            continue
        if value is None or (value == f.default and not f.spec.always):
            continue
        if f.base is bool:
            words.append(f.flag if value else "--no-" + f.flag[2:])
        elif f.base is dict:
            for key, item in value.items():
                words += [f.flag, f"{key}={item}"]
        elif f.base is list:
            for item in value:
                words += [f.flag, _text(f, item)]
        else:
            words += [f.flag, _text(f, value)]
    return words


# ----------------------------------------------------------------------------- commands
_ROLE = re.compile(r":[a-z]+:`~?([^`]+)`")
_LITERAL = re.compile(r"``([^`]+)``")


def plain(docstring: str) -> str:
    """A docstring as ``--help`` shows it: Sphinx roles and double backquotes dropped
    (``:func:`x``` and ````x```` read as ``x``)."""
    return _LITERAL.sub(r"\1", _ROLE.sub(r"\1", docstring))


def _shown(kwargs: dict[str, Any]) -> dict[str, Any]:
    """The ``add_argument`` keywords that ``--help`` shows, as JSON: no parsing function, and
    a default only where argparse prints it (a ``--flag/--no-flag``'s)."""
    shown = {k: v for k, v in kwargs.items() if k not in ("type", "default")}
    if kwargs.get("action") is argparse.BooleanOptionalAction:
        shown["action"] = "boolean_optional"
        shown["default"] = kwargs["default"]
    if "choices" in shown:
        shown["choices"] = [str(c) for c in shown["choices"]]
    return shown


@dataclass(frozen=True)
class Command:
    """A command: its settings dataclass, the function it runs, its help.

    Attributes
    ----------
    name : str
        The word on the command line.
    help : str
        One line for the list of commands.
    args : type or None
        The settings dataclass; the function gets an instance.
    run : callable or None
        ``run(args) -> exit code`` (None: 0).
    description : str
        The text above the options in ``--help``.
    subcommands : tuple of Command
        For a group (``rocketroll db ...``): the commands under it.
    aliases : tuple of str
        Former names of a renamed subcommand: still parsed for a release, left out of the
        list of commands, and a run under one says the new name on stderr.
    """

    name: str
    help: str
    args: type | None = None
    run: Callable[[Any], int | None] | None = None
    description: str = ""
    subcommands: tuple[Command, ...] = ()
    aliases: tuple[str, ...] = ()

    def parser(self, prog: str) -> ArgumentParser:
        """The full parser of this command (and of its subcommands)."""
        parser = ArgumentParser(
            prog=prog,
            description=plain(self.description or self.help),
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        self._fill(parser, prog)
        return parser

    def help_tree(self) -> dict[str, Any]:
        """What this command's parser is made of, as far as its help shows (JSON): the
        description, each option's flags, metavar, choices and help, the subcommands'
        trees; no parsing functions (:mod:`rocketroll.help` rebuilds the help from it)."""
        tree: dict[str, Any] = {"description": plain(self.description or self.help)}
        if self.subcommands:
            tree["dest"] = f"_{self.name}_command"
            tree["subcommands"] = [
                {"name": c.name, "help": c.help, "aliases": list(c.aliases), **c.help_tree()}
                for c in self.subcommands
            ]
        elif self.args is not None:
            tree["arguments"] = [
                [list(flags), _shown(kwargs)] for flags, kwargs in argument_specs(self.args)
            ]
        return tree

    def _fill(self, parser: argparse.ArgumentParser, prog: str) -> None:
        if self.subcommands:
            sub = parser.add_subparsers(
                dest=f"_{self.name}_command", required=True, metavar="COMMAND"
            )
            for command in self.subcommands:
                child = sub.add_parser(
                    command.name,
                    help=command.help,
                    description=plain(command.description or command.help),
                    formatter_class=argparse.RawDescriptionHelpFormatter,
                )
                command._fill(child, f"{prog} {command.name}")
                for alias in command.aliases:  # no help=: not in the list of commands
                    former = sub.add_parser(
                        alias,
                        description=plain(command.description or command.help),
                        formatter_class=argparse.RawDescriptionHelpFormatter,
                    )
                    command._fill(former, f"{prog} {command.name}")
                    former.set_defaults(_renamed=(f"{prog} {alias}", f"{prog} {command.name}"))
            return
        if self.args is not None:
            add_arguments(parser, self.args)
        parser.set_defaults(_command=self)


def _close_progress_bars() -> None:
    """Close live tqdm bars (an interrupt skips their ``close``; their ``__del__`` would
    then print "Exception ignored" at exit)."""
    tqdm_module = sys.modules.get("tqdm")
    if tqdm_module is None:
        return
    for bar in list(getattr(tqdm_module.tqdm, "_instances", ())):
        try:
            bar.close()
        except Exception:
            continue


@contextlib.contextmanager
def interrupts_held() -> Iterator[None]:
    """Hold a Ctrl-C that comes while the block runs (a file being written, which an
    interrupt would leave cut short) until the block is done, then raise it.  Where
    signals cannot be handled (not the main thread) the block runs as it is."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: caught.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if caught:
        raise KeyboardInterrupt


def guarded(prog: str, work: Callable[[], int | None]) -> int:
    """Run ``work`` as a command: the exit code, with user errors as one line.

    A :class:`RocketrollError` or an ``OSError`` about a named file prints
    ``PROG: error: ...`` on stderr and gives 2; Ctrl-C prints ``PROG:
    interrupted`` and gives 130; a closed output pipe ends quietly.
    """
    try:
        code = work()
    except RocketrollError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:
        _close_progress_bars()
        said = f": {exc}" if isinstance(exc, Interrupted) and str(exc) else ""
        print(f"\n{prog}: interrupted{said}", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`: stop quietly
        sys.stderr.close()
        return 0
    except OSError as exc:  # a file the user named cannot be read or written
        where = f": {exc.filename}" if exc.filename else ""
        print(f"{prog}: error: {exc.strerror or exc}{where}", file=sys.stderr)
        return 2
    except SystemError as exc:
        # Ctrl-C inside a compiled call (numba's dispatcher): Python reports the interrupt as
        # a SystemError caused by the KeyboardInterrupt ("returned a result with an
        # exception set").
        if not isinstance(exc.__cause__ or exc.__context__, KeyboardInterrupt):
            raise
        _close_progress_bars()
        print(f"\n{prog}: interrupted", file=sys.stderr)
        return 130
    return 0 if code is None else int(code)


def _files(cls: type, args: Any) -> Iterator[tuple[_Field, Any]]:
    """Every field of ``args`` (flattened ones opened) with its value."""
    for f in _fields(cls):
        value = getattr(args, f.name)
        if f.spec.flatten:
            yield from _files(f.base, value)
        else:
            yield f, value


def _paths(value: Any) -> list[str | os.PathLike[str]]:
    """The file paths a field's value names (none for a ``scheme://`` database)."""
    values = value if isinstance(value, list | tuple) else [value]
    return [v for v in values if isinstance(v, str | os.PathLike) and "://" not in str(v)]


def _check_files(cls: type, args: Any) -> None:
    """Refuse, before any work, outputs that cannot be written or would destroy a file the
    command did not make, and inputs that hold another kind of content than they should."""
    from rocketroll_common.files import KINDS, check_output, content_kind

    fields = list(_files(cls, args))
    # An input is named as the user gave it: by its flag, or (a positional) by its path,
    # not by the placeholder --help shows.
    inputs = [
        (f.shown, f.shown if not f.spec.positional else str(p), p)
        for f, value in fields
        if f.spec.input
        for p in _paths(value)
    ]
    for f, value in fields:
        if f.spec.output is not None and value is not None:
            names = f.spec.files(args) if callable(f.spec.files) else f.spec.files
            check_output(
                value,
                f.shown,
                folder=f.spec.output == "folder",
                kind=f.spec.kind,
                inputs=[(name, p) for shown, name, p in inputs if shown != f.shown],
                files=names or (),
            )
        elif f.spec.input and f.spec.kind is not None:
            for path in _paths(value):
                if Path(path).is_file():
                    found = content_kind(path)
                    if found not in (f.spec.kind, "empty"):
                        raise UsageError(
                            f"{f.shown} {path}: holds {KINDS[found]}, not {KINDS[f.spec.kind]}"
                        )


def renamed_note(old: str, new: str) -> None:
    """Say on stderr that the command ``old`` is now ``new`` (a renamed command's former
    name still runs for a release)."""
    print(f"{old}: renamed '{new}'; the old name goes in the next release", file=sys.stderr)


def run_command(command: Command, argv: Sequence[str], prog: str) -> int:
    """Parse ``argv`` for ``command``, check its outputs, run it; the exit code."""

    def work() -> int | None:
        ns = command.parser(prog).parse_args(list(argv))
        renamed = getattr(ns, "_renamed", None)
        if renamed is not None:
            renamed_note(*renamed)
        leaf: Command = ns._command
        if leaf.args is None or leaf.run is None:
            return leaf.run(None) if leaf.run is not None else 0
        from rocketroll_common.files import forcing

        args = from_namespace(leaf.args, ns)
        force = bool(_folder_outputs(leaf.args)) and bool(getattr(ns, "force", False))
        with forcing(force):  # --force: what rocketroll did not write is replaced
            _check_files(leaf.args, args)
            return leaf.run(args)

    return guarded(prog, work)
