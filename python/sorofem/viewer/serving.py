"""Starting and stopping the viewer's server: the optional dependency viser, and the wait for Ctrl-C."""

from __future__ import annotations

import time
from typing import Any

from ..errors import InputError

__all__ = ["require_viser", "wait_until_interrupted"]


def require_viser() -> Any:
    """The ``viser`` module, or an :class:`InputError` saying how to install it."""
    try:
        import viser
    except ImportError:
        raise InputError(
            "sorofem view needs the optional dependency viser: pip install \".[viewer]\" from a checkout of "
            "sorofem (or pip install 'viser>=1.1,<1.2' trimesh)"
        ) from None
    return viser


def wait_until_interrupted(server: Any, on_stop: Any = None) -> None:
    """Wait until Ctrl-C, then call ``on_stop`` and stop the server."""
    try:
        while True:
            time.sleep(1.0)
    except KeyboardInterrupt:
        pass
    finally:
        if on_stop is not None:
            on_stop()
        server.stop()
