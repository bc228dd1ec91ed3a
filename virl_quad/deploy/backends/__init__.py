"""Robot backends: ``get_backend(name, **kw)`` -> :class:`Backend` (see ``base``)."""

from virl_quad.deploy.backends.base import (
    BACKENDS,
    Backend,
    BackendError,
    BackendTimeout,
    LoopbackBackend,
    backend_names,
    check_command,
    get_backend,
    register_backend,
    resolve_spec,
)

__all__ = [
    "BACKENDS", "Backend", "BackendError", "BackendTimeout", "LoopbackBackend", "backend_names",
    "check_command", "get_backend", "register_backend", "resolve_spec",
]
