"""Starting and stopping the viewer's server: the optional dependency viser, one view per
browser tab (:func:`per_client`), the camera, and the wait for Ctrl-C."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Generic, TypeVar

from ..errors import InputError

__all__ = ["require_viser", "wait_until_interrupted", "PerClient", "per_client", "place_camera", "CORE_LOCK"]

V = TypeVar("V")

#: Held around every solve and simulation the viewer runs: views on copies of a body made by
#: ``Body.replace`` share its compiled model, which solves one problem at a time (``sorofem
#: view`` gives each tab a model of its own; the lock still keeps tabs from competing for cores).
CORE_LOCK = threading.RLock()


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


def place_camera(target: Any, look_at: Any, position: Any) -> None:
    """Point the camera of ``target``: a ``viser.ViserServer`` (the camera each new tab starts
    with) or a ``viser.ClientHandle`` (that tab's camera)."""
    look_at, position = tuple(float(v) for v in look_at), tuple(float(v) for v in position)
    if hasattr(target, "initial_camera"):
        target.initial_camera.look_at, target.initial_camera.position = look_at, position
    else:
        # A tab moves its camera keeping the view direction when the position changes (the
        # target moves along): the position first, then what it looks at.
        target.camera.position = position
        target.camera.look_at = look_at


@dataclass
class PerClient(Generic[V]):
    """One view per browser tab connected to ``server``, each drawn on its tab's own scene and
    controls (a ``viser.ClientHandle``), so that one tab's sliders, checkboxes and playback do
    not move another's. Built by :func:`per_client`.

    Attributes
    ----------
    server
        The ``viser.ViserServer``.
    views
        ``{client_id: view}`` of the tabs connected now (a tab that reloads is a new client).
    """

    server: Any
    build: Callable[[Any], V]
    views: dict[int, V] = field(default_factory=dict)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    _closed: bool = field(default=False, repr=False)

    def _connect(self, client: Any) -> None:
        view = self.build(client)
        with self._lock:
            if not self._closed:
                self.views[client.client_id] = view
                return
        _close(view)

    def _disconnect(self, client: Any) -> None:
        with self._lock:
            view = self.views.pop(client.client_id, None)
        if view is not None:
            _close(view)

    def wait_for(self, count: int = 1, timeout: float = 10.0) -> list[V]:
        """The views once ``count`` tabs are connected and built (in connection order), or
        :class:`TimeoutError` after ``timeout`` seconds."""
        deadline = time.monotonic() + timeout
        while True:
            with self._lock:
                if len(self.views) >= count:
                    return [self.views[k] for k in sorted(self.views)]
            if time.monotonic() > deadline:
                raise TimeoutError(f"{len(self.views)} of {count} browser tabs connected after {timeout:g} s")
            time.sleep(0.01)

    def close(self) -> None:
        """Close every tab's view (stops their playback and simulations); the server is the
        caller's to stop."""
        with self._lock:
            self._closed = True
            views, self.views = list(self.views.values()), {}
        for view in views:
            _close(view)


def _close(view: Any) -> None:
    close = getattr(view, "close", None)
    if close is not None:
        close()


def per_client(server: Any, build: Callable[[Any], V]) -> PerClient[V]:
    """Give each browser tab that connects to ``server`` its own view, ``build(client)`` (drawn
    on ``client.scene`` and ``client.gui``), closed when the tab goes.

    Examples
    --------
    >>> tabs = per_client(server, lambda client: build_view(scene, client))  # doctest: +SKIP
    >>> tabs.wait_for(2)[0].sliders[0].value = 0.7   # moves the first tab only  # doctest: +SKIP
    """
    tabs: PerClient[V] = PerClient(server, build)
    server.on_client_disconnect(tabs._disconnect)
    server.on_client_connect(tabs._connect)
    return tabs
