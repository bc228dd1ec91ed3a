"""Command-line plumbing shared by the entry modules.

- :class:`Parser`: argparse with one-line errors (``error: ...``, exit code 2, no usage
  block) and every option's default in its help; every entry module uses it.
- :func:`opt`: a dataclass field that carries its command-line help (and choices).
- :func:`parser_from_dataclass`: a :class:`Parser` with one option per field of such a
  dataclass (cleanrl's pattern: the dataclass is the CLI and its documentation).
- :func:`run_main`: run a ``main`` and turn expected failures (bad input) into one
  line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
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


def opt(default: Any, help: str, choices: Sequence[str] | None = None) -> Any:
    """A dataclass field with default ``default`` whose ``--option`` shows ``help`` (and accepts
    only ``choices``, when given)."""
    meta: dict[str, Any] = {"help": help}
    if choices is not None:
        meta["choices"] = tuple(choices)
    return dataclasses.field(default=default, metadata=meta)


def _arg_type(tp: Any) -> Callable | None:
    """The argparse converter of a field annotation; None for a bool (a --flag/--no-flag switch)."""
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    base = args[0] if len(args) == 1 else tp  # "X | None" -> X
    if base is bool:
        return None
    return base if base in (int, float, str) else str


def _help(f: dataclasses.Field) -> str:
    return str(f.metadata.get("help", "")).replace("%", "%%")   # argparse formats help with %


def parser_from_dataclass(cls: type, description: str = "", **kwargs: Any) -> argparse.ArgumentParser:
    """A :class:`Parser` with one ``--kebab-case`` option per field of dataclass ``cls``."""
    parser = Parser(description=description, **kwargs)
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        flag = "--" + f.name.replace("_", "-")
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore
        conv = _arg_type(hints[f.name])
        choices = f.metadata.get("choices")
        if conv is None:  # bool: --flag / --no-flag
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=default,
                                help=_help(f))
        else:
            parser.add_argument(flag, type=conv, default=default, choices=choices, dest=f.name,
                                help=_help(f))
    return parser


def dataclass_from_args(cls: type, ns: argparse.Namespace) -> Any:
    """Build ``cls`` from the parsed namespace (fields only)."""
    names = {f.name for f in dataclasses.fields(cls)}
    return cls(**{k: v for k, v in vars(ns).items() if k in names})


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
