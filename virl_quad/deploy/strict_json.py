"""Strict JSON for the wire protocol's JSON payloads (ANNOUNCE, STATUS, ESTOP, ARM).

Python's :func:`json.loads` accepts what other parsers read differently, so a message could
mean one thing to the HAL and another to a policy server. :func:`loads_strict` refuses it:
``NaN``/``Infinity``, numbers that overflow a double (``1e400``), and duplicated member names.
"""

from __future__ import annotations

import json
import math
from typing import Any


def loads_strict(text: str) -> Any:
    """``text`` parsed as JSON; ValueError on a non-finite number or a duplicated member name
    (RecursionError on absurd nesting, as :func:`json.loads`)."""
    return json.loads(text, parse_constant=_reject_constant, parse_float=_finite_float,
                      object_pairs_hook=_unique_object)


def _reject_constant(name: str) -> None:
    raise ValueError(f"non-finite JSON number {name}")


def _finite_float(text: str) -> float:
    """A JSON number as float; ValueError when it overflows to infinity (e.g. ``1e400``)."""
    value = float(text)
    if not math.isfinite(value):
        raise ValueError(f"JSON number {text[:20]} is not a finite double")
    return value


def _unique_object(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    """A JSON object as dict; ValueError on a duplicated member name (which value wins is
    ambiguous between parsers, so neither does)."""
    seen: set[str] = set()
    for name, _ in pairs:
        if name in seen:
            raise ValueError(f"duplicated member {name[:40]!r}")
        seen.add(name)
    return dict(pairs)
