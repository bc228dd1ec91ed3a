"""Zenoh session configuration from the json5 files in ``deploy/zenoh/``.

>>> conf = load_config("peer", listen=[], connect=["tcp/127.0.0.1:7447"])  # doctest: +SKIP
>>> with zenoh.open(conf) as session:                                      # doctest: +SKIP
...     session.put(protocol.key("pupper-01", "estop"), data)

Sessions are always opened with ``with zenoh.open(conf) as s:`` so they are closed.
"""

from __future__ import annotations

import json
import socket
from pathlib import Path
from typing import Any, Iterable, Union

import zenoh

#: Folder of the project's Zenoh configuration files.
CONFIG_DIR: Path = Path(__file__).resolve().parents[2] / "deploy" / "zenoh"

#: Config keys holding file paths; relative ones are resolved against the json5 file's folder.
PATH_KEYS: tuple[str, ...] = (
    "transport/auth/usrpwd/dictionary_file",
    "transport/link/tls/root_ca_certificate",
    "transport/link/tls/listen_certificate",
    "transport/link/tls/listen_private_key",
    "transport/link/tls/connect_certificate",
    "transport/link/tls/connect_private_key",
)

Endpoints = Union[str, Iterable[str], None]

#: where a policy server or an operator looks for the HAL when neither the command line nor the
#: Zenoh config names an endpoint: the HAL's listen endpoint in deploy/zenoh/peer.json5
DEFAULT_CONNECT = "tcp/127.0.0.1:7447"


def config_path(name: Union[str, Path]) -> Path:
    """Path of a config: a file path, or a name in CONFIG_DIR ("peer", "secure", ...)."""
    p = Path(name)
    if p.suffix != ".json5" and p.parent == Path("."):
        p = CONFIG_DIR / f"{name}.json5"
    if not p.is_file():
        choices = ", ".join(sorted(f.stem for f in CONFIG_DIR.glob("*.json5")))
        raise FileNotFoundError(f"no Zenoh config {str(p)!r}; named configs: {choices}")
    return p


def _endpoints(value: Endpoints) -> list[str]:
    return [value] if isinstance(value, str) else list(value or [])


def load_config(path: Union[str, Path], listen: Endpoints = None, connect: Endpoints = None,
                overrides: dict[str, Any] | None = None) -> zenoh.Config:
    """Load a json5 config and apply overrides.

    ``listen`` / ``connect``: endpoint or list of endpoints replacing the file's (``[]``
    clears them; None keeps the file's). ``overrides``: {"a/b/c": value} inserted as JSON,
    e.g. {"transport/auth/usrpwd/user": "policy"}. Relative paths under PATH_KEYS (from
    the file or the overrides) are resolved against the file's folder.
    """
    p = config_path(path)
    conf = zenoh.Config.from_file(str(p))
    if listen is not None:
        conf.insert_json5("listen/endpoints", json.dumps(_endpoints(listen)))
    if connect is not None:
        conf.insert_json5("connect/endpoints", json.dumps(_endpoints(connect)))
    for k, v in (overrides or {}).items():
        conf.insert_json5(k, json.dumps(v))
    for k in PATH_KEYS:
        v = json.loads(conf.get_json(k))
        if isinstance(v, str) and not Path(v).is_absolute():
            conf.insert_json5(k, json.dumps(str((p.parent / v).resolve())))
    return conf


def free_port(host: str = "127.0.0.1") -> int:
    """A TCP port free on ``host`` right now (for tests choosing listen endpoints)."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind((host, 0))
        return int(s.getsockname()[1])


def publisher_options(topic: str) -> dict[str, Any]:
    """Recommended ``declare_publisher`` / ``put`` keyword arguments for a protocol topic.

    cmd and state: newest-wins real-time traffic (drop under congestion, no batching);
    estop and arm: must arrive (block under congestion), highest priority for estop.
    """
    P, C = zenoh.Priority, zenoh.CongestionControl
    table: dict[str, dict[str, Any]] = {
        "cmd": dict(priority=P.REAL_TIME, congestion_control=C.DROP, express=True),
        "estop": dict(priority=P.REAL_TIME, congestion_control=C.BLOCK, express=True),
        "state": dict(priority=P.INTERACTIVE_HIGH, congestion_control=C.DROP, express=True),
        "arm": dict(priority=P.INTERACTIVE_HIGH, congestion_control=C.BLOCK),
        "status": dict(priority=P.DATA, congestion_control=C.DROP),
        "announce": dict(priority=P.DATA, congestion_control=C.BLOCK),
    }
    if topic not in table:
        raise ValueError(f"unknown topic {topic!r}; choose one of: {', '.join(table)}")
    return dict(table[topic])
