"""Deployment: wire protocol, safety layer, robot backends and Zenoh configuration.

- :mod:`virl_quad.deploy.protocol`     message layouts, key expressions (``deploy/PROTOCOL.md``)
- :mod:`virl_quad.deploy.safety`       IDLE -> RAMP -> ACTIVE -> DAMPING, command validation
- :mod:`virl_quad.deploy.backends`     ``Backend`` interface, ``get_backend(name, **kw)``
- :mod:`virl_quad.deploy.zenoh_config` ``load_config("peer" | "secure" | ..., listen=, connect=)``
- :mod:`virl_quad.deploy.hal`          ``python -m virl_quad.deploy.hal``: robot + safety layer on Zenoh
- :mod:`virl_quad.deploy.serve`        ``python -m virl_quad.deploy.serve``: TorchScript policy server
- :mod:`virl_quad.deploy.operator`     ``python -m virl_quad.deploy.operator status|arm|estop``

Usage: ``deploy/README.md``.

Importing this package does not import zenoh or pyserial.
"""

from virl_quad.deploy.protocol import (
    JointCommand,
    Message,
    MsgType,
    ProtocolError,
    RobotState,
    SeqCounter,
    decode,
    encode_command,
    encode_json,
    encode_state,
    key,
    liveliness_key,
)
from virl_quad.deploy.safety import Mode, SafetyConfig, SafetyController, is_safe_command

__all__ = [
    "JointCommand", "Message", "MsgType", "ProtocolError", "RobotState", "SeqCounter", "decode", "encode_command",
    "encode_json", "encode_state", "key", "liveliness_key",
    "Mode", "SafetyConfig", "SafetyController", "is_safe_command",
]
