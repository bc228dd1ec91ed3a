"""Command-line plumbing shared by the entry modules.

- :class:`Parser`: argparse with one-line errors (``error: ...``, exit code 2, no usage
  block) and every option's default in its help; every entry module uses it.
- :func:`opt`: a dataclass field that carries its command-line help (and choices).
- :func:`parser_from_dataclass`: a :class:`Parser` with one option per field of such a
  dataclass (cleanrl's pattern: the dataclass is the CLI and its documentation); a field that
  is itself such a dataclass is a section (one concern) whose options form a group in the help.
  Option names are flat and unique across sections (``--reward-lr``, not ``--distance.reward-lr``).
  :func:`parse` builds the dataclass from a command line with it.
- :func:`options`, :func:`from_options`, :func:`replace_options`: the same options as one flat
  ``{name: value}`` dict (how a run's configuration is saved), and back; :class:`Sectioned`
  gives such a dataclass ``make(**flat_names)``.
- :func:`run_main`: run a ``main`` and turn expected failures (bad input) into one
  line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import types
import typing
from collections.abc import Sequence
from typing import Any, Callable

class UserError(Exception):
    """A failure caused by the user's input; shown as one line, exit code 2."""


class _DefaultsHelp(argparse.ArgumentDefaultsHelpFormatter):
    """Help texts end with the option's default, unless it is required or has none (None, "")."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.required or action.default is None or action.default == "":
            return action.help
        return super()._get_help_string(action)


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one ``error: ...`` line (exit code 2) and whose help
    shows each option's default. Subcommand parsers made from it are of the same kind."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _DefaultsHelp)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> typing.NoReturn:  # argparse's hook for a bad command line
        """Print ``error: <message>`` on stderr and exit 2 (argparse prints the usage block too)."""
        print(f"error: {message}", file=sys.stderr)
        sys.exit(2)


def opt(default: Any, help: str, choices: Sequence[str] | None = None, positional: bool = False,
        required: bool = False, nargs: str | None = None) -> Any:
    """A dataclass field with default ``default`` whose ``--option`` shows ``help`` (and accepts
    only ``choices``, when given); ``positional``: a positional argument instead; ``required``:
    the command line must give it (the default then only serves code that builds the dataclass);
    ``nargs="+"``: a list option takes its items after one flag (else the flag repeats).
    Only fields made with :func:`opt` appear on the command line."""
    meta: dict[str, Any] = {"help": help, "positional": positional, "required": required, "nargs": nargs}
    if choices is not None:
        meta["choices"] = tuple(choices)
    if isinstance(default, list):                 # a mutable default: each instance its own copy
        return dataclasses.field(default_factory=lambda: list(default), metadata=meta)
    return dataclasses.field(default=default, metadata=meta)


def _arg_type(tp: Any) -> tuple[Callable | None, bool]:
    """(argparse converter, repeatable) of a field annotation: converter None for a bool (a
    --flag/--no-flag switch); a list is a repeatable option of its items."""
    union = typing.get_origin(tp) in (typing.Union, types.UnionType)
    args = [a for a in typing.get_args(tp) if a is not type(None)] if union else []
    base = args[0] if len(args) == 1 else tp  # "X | None" -> X
    if typing.get_origin(base) is list:
        item = (typing.get_args(base) or (str,))[0]
        return (item if item in (int, float, str) else str), True
    if base is bool:
        return None, False
    return (base if base in (int, float, str) else str), False


def _help(f: dataclasses.Field) -> str:
    return str(f.metadata.get("help", "")).replace("%", "%%")   # argparse formats help with %


def _sections(cls: type) -> list[tuple[str | None, type, list[dataclasses.Field]]]:
    """``(section name or None, dataclass, its option fields)``: the top level's plain options
    first, then one entry per field whose type is a dataclass."""
    hints = typing.get_type_hints(cls)
    plain = [f for f in dataclasses.fields(cls) if not dataclasses.is_dataclass(hints[f.name])]
    out: list[tuple[str | None, type, list[dataclasses.Field]]] = [(None, cls, plain)] if plain else []
    for f in dataclasses.fields(cls):
        sub = hints[f.name]
        if dataclasses.is_dataclass(sub):
            out.append((f.name, sub, list(dataclasses.fields(sub))))
    return out


def _default(f: dataclasses.Field) -> Any:
    return f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore


def parser_from_dataclass(cls: type, description: str = "", **kwargs: Any) -> argparse.ArgumentParser:
    """A :class:`Parser` with one ``--kebab-case`` option per field of dataclass ``cls`` (and of
    its sections, each an argument group titled by the section's docstring)."""
    parser = Parser(description=description, **kwargs)
    add_options(parser, cls)
    return parser


def add_options(parser: argparse.ArgumentParser, cls: type) -> None:
    """Add the options of dataclass ``cls`` (see :func:`parser_from_dataclass`) to ``parser``
    (e.g. a subcommand's parser)."""
    seen: set[str] = set()
    for section, sub, flds in _sections(cls):
        doc = (sub.__doc__ or "").strip().splitlines()[0] if section else ""
        group = parser.add_argument_group(f"{section} ({doc.rstrip('.')})" if doc else section) if section else parser
        hints = typing.get_type_hints(sub)
        for f in flds:
            if "help" not in f.metadata:
                continue                          # a setting, not a command-line option
            if f.name in seen:
                raise TypeError(f"option --{f.name.replace('_', '-')} is defined twice in {cls.__name__}")
            seen.add(f.name)
            _add(group, f, hints[f.name])


def _add(group: Any, f: dataclasses.Field, hint: Any) -> None:
    """One argparse argument for option field ``f``."""
    conv, repeat = _arg_type(hint)
    choices, default, required = f.metadata.get("choices"), _default(f), bool(f.metadata.get("required"))
    if f.metadata.get("positional"):
        group.add_argument(f.name, nargs=None if required else "?", type=conv, default=default, choices=choices,
                           help=_help(f))
    elif required:
        group.add_argument("--" + f.name.replace("_", "-"), type=conv, required=True, choices=choices,
                           dest=f.name, help=_help(f))
    elif conv is None:  # bool: --flag, and --no-flag when it is on by default
        group.add_argument("--" + f.name.replace("_", "-"), default=default, help=_help(f),
                           action=argparse.BooleanOptionalAction if default else "store_true")
    elif repeat and f.metadata.get("nargs"):
        group.add_argument("--" + f.name.replace("_", "-"), type=conv, nargs=f.metadata["nargs"], default=default,
                           dest=f.name, help=_help(f))
    elif repeat:
        group.add_argument("--" + f.name.replace("_", "-"), type=conv, action="append", default=None,
                           dest=f.name, help=_help(f) + " (repeatable)")
    else:
        group.add_argument("--" + f.name.replace("_", "-"), type=conv, default=default, choices=choices,
                           dest=f.name, help=_help(f))


def parse(cls: type, argv: list[str] | None, description: str, prog: str) -> Any:
    """``cls`` from the command line ``argv`` (None: ``sys.argv[1:]``) through
    :func:`parser_from_dataclass`: one ``error:`` line and exit 2 for bad input."""
    parser = parser_from_dataclass(cls, description=description, prog=prog)
    return dataclass_from_args(cls, parser.parse_args(sys.argv[1:] if argv is None else argv))


def from_options(cls: type, values: dict[str, Any]) -> Any:
    """``cls`` (sections included) from a flat ``{option name: value}`` dict; options it does not
    name keep their defaults, names ``cls`` does not know are ignored (settings saved by an older
    version)."""
    top: dict[str, Any] = {}
    for section, sub, flds in _sections(cls):
        mine = {f.name: values[f.name] for f in flds if f.name in values}
        if section is None:
            top.update(mine)
        else:
            top[section] = sub(**mine)
    return cls(**top)


def dataclass_from_args(cls: type, ns: argparse.Namespace) -> Any:
    """Build ``cls`` (sections included) from the parsed namespace."""
    return from_options(cls, vars(ns))


def options(obj: Any) -> dict[str, Any]:
    """The flat ``{option name: value}`` dict of a dataclass instance with sections (the values
    themselves, not copies)."""
    out: dict[str, Any] = {}
    for section, _, flds in _sections(type(obj)):
        holder = obj if section is None else getattr(obj, section)
        out.update({f.name: getattr(holder, f.name) for f in flds})
    return out


def replace_options(obj: Any, **values: Any) -> Any:
    """A copy of ``obj`` with the named options (flat names) replaced; TypeError for an unknown one."""
    unknown = set(values) - set(options(obj))
    if unknown:
        raise TypeError(f"unknown option(s): {', '.join(sorted(unknown))}")
    return from_options(type(obj), {**options(obj), **values})


class Sectioned:
    """Base of a dataclass whose fields are options and sections of options (flat names).

    A field annotated with a dataclass and given no default is a section: it defaults to that
    dataclass's defaults (``env: EnvOptions`` means ``field(default_factory=EnvOptions)``).
    """

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        module = sys.modules[cls.__module__].__dict__
        for name, hint in cls.__dict__.get("__annotations__", {}).items():
            if name in cls.__dict__:
                continue
            try:
                kind = eval(hint, module) if isinstance(hint, str) else hint  # the module's own annotation
            except Exception:
                continue
            if dataclasses.is_dataclass(kind):
                setattr(cls, name, dataclasses.field(default_factory=kind))

    @classmethod
    def make(cls, **values: Any) -> Any:
        """An instance with the named options (flat names, ``make(num_envs=4)``) changed from the
        defaults; TypeError for an unknown name."""
        return replace_options(cls(), **values)


def run_main(main: Callable[[], int | None]) -> None:
    """Run ``main``; bad input becomes ``error: ...`` on stderr and exit code 2; Ctrl-C exits 130."""
    try:
        code = main()
    except (UserError, ValueError, FileNotFoundError) as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"error: {msg}", file=sys.stderr)
        sys.exit(2)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(130)
    sys.exit(code or 0)
