"""Command-line plumbing shared by the entry modules.

- :class:`Parser`: argparse with one-line errors (``error: ...``, exit code 2, no usage
  block) and every option's default in its help; every entry module uses it.
- :func:`parser_from_dataclass`: a :class:`Parser` whose options are a dataclass's
  fields and whose help texts are the fields' trailing ``# comments``.
- :func:`run_main`: run a ``main`` and turn expected failures (bad input) into one
  line on stderr and exit code 2, never a traceback.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import re
import sys
import typing
from typing import Any, Callable

_FIELD = re.compile(r"^\s+(\w+)\s*:\s*[^=#]+(?:=[^#]*)?#\s*(.+?)\s*$")


class UserError(Exception):
    """A failure caused by the user's input; shown as one line, exit code 2."""


class _DefaultsHelp(argparse.ArgumentDefaultsHelpFormatter):
    """Help texts end with the option's default, unless it is required or has none."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        if action.required or action.default is None:
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


def field_comments(cls: type) -> dict[str, str]:
    """Map each field of dataclass ``cls`` to the comment written after it in the source."""
    out: dict[str, str] = {}
    for line in inspect.getsource(cls).splitlines():
        m = _FIELD.match(line)
        if m:
            out[m.group(1)] = m.group(2)
    return out


def _arg_type(tp: Any) -> Callable | None:
    """The argparse converter of a field annotation; None for a bool (a --flag/--no-flag switch)."""
    args = [a for a in typing.get_args(tp) if a is not type(None)]
    base = args[0] if len(args) == 1 else tp  # "X | None" -> X
    if base is bool:
        return None
    return base if base in (int, float, str) else str


def parser_from_dataclass(cls: type, description: str = "", **kwargs: Any) -> argparse.ArgumentParser:
    """A :class:`Parser` with one ``--kebab-case`` option per field of dataclass ``cls``."""
    parser = Parser(description=description, **kwargs)
    helps = {k: v.replace("%", "%%") for k, v in field_comments(cls).items()}  # argparse formats help with %
    hints = typing.get_type_hints(cls)
    for f in dataclasses.fields(cls):
        flag = "--" + f.name.replace("_", "-")
        default = f.default if f.default is not dataclasses.MISSING else f.default_factory()  # type: ignore
        conv = _arg_type(hints[f.name])
        choices = f.metadata.get("choices")
        if conv is None:  # bool: --flag / --no-flag
            parser.add_argument(flag, action=argparse.BooleanOptionalAction, default=default,
                                help=helps.get(f.name, ""))
        else:
            parser.add_argument(flag, type=conv, default=default, choices=choices, dest=f.name,
                                help=helps.get(f.name, ""))
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
