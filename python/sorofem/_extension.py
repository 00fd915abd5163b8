"""The compiled extension ``sorofem._core``, with a message that says how to build it when it is missing.

Internal: every module that calls the Rust core gets it through :func:`core`, so that importing
sorofem works before ``make build`` (the pure-Python parts, the scene schema) and the first call
that needs the core says what to do.
"""

from __future__ import annotations

from typing import Any

try:
    from . import _core
except ImportError as _exc:  # pragma: no cover - only before `make build`
    _core = None
    _IMPORT_ERROR: ImportError | None = _exc
else:
    _IMPORT_ERROR = None

__all__ = ["core"]


def core() -> Any:
    """The module ``sorofem._core``.

    Raises
    ------
    ImportError
        The extension has not been built (``make build``).
    """
    if _core is None:
        raise ImportError(
            "the compiled extension sorofem._core is not available; build it with `make build`"
        ) from _IMPORT_ERROR
    return _core
