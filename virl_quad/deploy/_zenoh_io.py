"""Small helpers shared by the HAL and the policy server (not a public API).

- :func:`open_config`: a Zenoh config from a name or path, with one-line errors
- :class:`SeqPublisher`: a declared publisher that frames protocol messages with its own
  sequence counter (thread-safe)
- :class:`StopFlag`: SIGINT / SIGTERM -> an Event, for loops that must exit cleanly
- :class:`Log`: one-line messages on stderr, with "log once" keys
- :func:`undeclare_all`: undeclare entities in reverse order, never raising
"""

from __future__ import annotations

import signal
import sys
import threading
from typing import Any, Callable, Iterable, Sequence

import zenoh

from virl_quad.cli import UserError
from virl_quad.deploy import protocol as P
from virl_quad.deploy.zenoh_config import load_config, publisher_options


def open_config(name: str, listen: Sequence[str] | None = None,
                connect: Sequence[str] | None = None) -> zenoh.Config:
    """Load a Zenoh config (``deploy/zenoh/<name>.json5`` or a file path); endpoint lists
    replace the file's unless None. Bad files become a UserError (one line, exit 2)."""
    try:
        return load_config(name, listen=listen, connect=connect)
    except FileNotFoundError:
        raise
    except Exception as e:   # zenoh.ZError (json5 syntax, unknown keys) and friends
        where = f"Zenoh config {name!r}" + (" or endpoints" if listen or connect else "")
        raise UserError(f"bad {where}: {_first_line(e)}") from None


def open_session(conf: zenoh.Config) -> zenoh.Session:
    """``zenoh.open(conf)`` with a one-line UserError (e.g. port in use, missing certificate)."""
    try:
        return zenoh.open(conf)
    except Exception as e:   # zenoh.ZError
        raise UserError(f"cannot open the Zenoh session: {_first_line(e)}") from None


def _first_line(e: BaseException) -> str:
    """First line of an error message, without the Rust source locations zenoh appends."""
    text = str(e).strip()
    line = text.splitlines()[0] if text else type(e).__name__
    return line.split(" at /")[0][:200]


class SeqPublisher:
    """A publisher for one protocol topic that stamps each message with the next sequence
    number of its own :class:`~virl_quad.deploy.protocol.SeqCounter`."""

    def __init__(self, session: zenoh.Session, robot_id: str, topic: str) -> None:
        self.key = P.key(robot_id, topic)
        self.pub = session.declare_publisher(self.key, **publisher_options(topic))
        self._seq = P.SeqCounter()
        self._lock = threading.Lock()

    def put(self, encode: Callable[[int], bytes]) -> int:
        """Publish ``encode(seq)``; returns the sequence number used."""
        with self._lock:
            seq = self._seq()
            self.pub.put(encode(seq))
        return seq

    def undeclare(self) -> None:
        """Undeclare the underlying publisher."""
        self.pub.undeclare()


class StopFlag:
    """Sets an Event on SIGINT / SIGTERM (main thread only); restores the old handlers."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signum: int | None = None
        self._old: dict[int, Any] = {}

    def __enter__(self) -> "StopFlag":
        if threading.current_thread() is threading.main_thread():
            for s in (signal.SIGINT, signal.SIGTERM):
                self._old[s] = signal.signal(s, self._handle)
        return self

    def _handle(self, signum: int, _frame: Any) -> None:
        self.signum = signum
        self.event.set()

    def __exit__(self, *exc: object) -> None:
        for s, h in self._old.items():
            signal.signal(s, h)

    def is_set(self) -> bool:
        """True once a stop was requested."""
        return self.event.is_set()

    def wait(self, timeout: float) -> bool:
        """Sleep up to ``timeout`` s (returns early, True, when stopped)."""
        return self.event.wait(max(0.0, timeout))


class Log:
    """``prog: message`` lines on stderr; :meth:`once` prints a key's first message only."""

    def __init__(self, prog: str, quiet: bool = False) -> None:
        self.prog = prog
        self.quiet = quiet
        self._seen: set[str] = set()
        self._lock = threading.Lock()

    def __call__(self, msg: str) -> None:
        """Print one line (unless quiet)."""
        if not self.quiet:
            print(f"{self.prog}: {msg}", file=sys.stderr, flush=True)

    def once(self, key: str, msg: str) -> None:
        """Print ``msg`` the first time ``key`` is seen."""
        with self._lock:
            if key in self._seen:
                return
            self._seen.add(key)
        self(msg)


def undeclare_all(entities: Iterable[Any]) -> None:
    """Undeclare Zenoh entities (publishers, subscribers, queryables, tokens) in reverse order;
    errors (e.g. an already closed session) are ignored."""
    for e in reversed(list(entities)):
        try:
            e.undeclare()
        except Exception:
            pass
