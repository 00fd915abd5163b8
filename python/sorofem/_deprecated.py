"""Names that moved, kept importable from their old place for one release with a DeprecationWarning.

:func:`moved` builds a module-level ``__getattr__`` (PEP 562) that answers a module's old names
with a warning. A module whose old name now lives in a layer above it (``sorofem.cables.actuate``,
now :func:`sorofem.static.actuate`) gets its ``__getattr__`` from the package's ``__init__``,
after every layer is imported, so that no layer imports a higher one. ``sorofem.model`` (the old
home of Mesh, NeoHookean, Body and the static solve) is a module of its own that warns when imported.
"""

from __future__ import annotations

import warnings
from typing import Any, Callable

__all__ = ["moved"]


def moved(module: str, names: dict[str, tuple[Callable[[], Any], str]]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``module``'s deprecated ``names``: name -> (a function
    returning the object, what to use instead)."""

    def __getattr__(name: str) -> Any:
        if name in names:
            value, instead = names[name]
            warnings.warn(f"{module}.{name} is deprecated; use {instead}", DeprecationWarning, stacklevel=2)
            return value()
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__
