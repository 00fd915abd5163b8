"""A small progress line on stderr for long runs (time integration, inverse problems).

:func:`sorofem.simulate`, :func:`sorofem.estimate` and :func:`sorofem.control` take
``progress=``:

* ``None`` (default): automatic, a line is drawn only when stderr is a terminal (``isatty()``)
  and only once the run has lasted :data:`DELAY` seconds, so quick calls print nothing. Under
  CI, in a pipe, redirected to a file or in Jupyter (whose stderr is not a terminal) nothing is
  written.
* ``True``: always draw it, from the start (e.g. in Jupyter, which renders the carriage
  returns).
* ``False``: never.

The line is rewritten in place with carriage returns (no terminal control sequences), fits the
terminal width, shows the elapsed time and, when the total is known, a bar, the percentage
and the estimated time left; a final newline leaves the last state on screen. It never raises
because of the terminal: a closed or broken stream silently ends the drawing.

:func:`default` changes what ``progress=None`` means within a ``with`` block, for a caller
that knows better, e.g. a command line with ``--quiet``.

Examples
--------
>>> import sys
>>> from sorofem.progress import Progress
>>> with Progress(total=3, desc="work", unit="steps", enabled=False) as bar:  # silent
...     for _ in range(3):
...         bar.update(1, postfix="loss 1e-3")
>>> bar.done
3
"""

from __future__ import annotations

import math
import shutil
import sys
import threading
import time
from contextlib import contextmanager
from contextvars import ContextVar
from typing import IO, Any, Iterator

__all__ = ["Progress", "DELAY", "default", "is_enabled", "format_duration"]

#: Seconds an automatic (``progress=None``) line waits before it first appears.
DELAY = 0.5
#: Smallest interval between two redraws, s (the last state is always drawn).
MIN_INTERVAL = 0.1
#: An active line redraws itself this often, s, so the clock moves during one long call.
REFRESH = 0.5

_DEFAULT: ContextVar[bool | None] = ContextVar("sorofem_progress_default", default=None)


@contextmanager
def default(progress: bool | None) -> Iterator[None]:
    """Within the block, ``progress=None`` means ``progress`` (``False``: silent, ``True``:
    always, ``None``: automatic). An explicit ``progress=True/False`` argument still wins.

    Examples
    --------
    >>> import sorofem as sf
    >>> with sf.progress.default(False):              # e.g. for a --quiet command line
    ...     pass                                      # sf.simulate(...) draws nothing here
    """
    token = _DEFAULT.set(progress)
    try:
        yield
    finally:
        _DEFAULT.reset(token)


def _isatty(stream: Any) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, OSError, ValueError):
        return False


def is_enabled(progress: bool | None, stream: Any = None) -> bool:
    """Whether a progress line would be drawn on ``stream`` (default ``sys.stderr``)."""
    if progress is None:
        progress = _DEFAULT.get()
    if progress is None:
        return _isatty(sys.stderr if stream is None else stream)
    return bool(progress)


def format_duration(seconds: float) -> str:
    """``m:ss`` below an hour, ``h:mm:ss`` above; ``?`` when unknown."""
    if not math.isfinite(seconds) or seconds < 0:
        return "?"
    s = int(round(seconds))
    h, rest = divmod(s, 3600)
    m, s = divmod(rest, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class Progress:
    """One progress line, redrawn in place on ``stream``.

    Parameters
    ----------
    total
        Number of units of work, or ``None`` when unknown (then no bar, no percentage and no
        ETA: a count and the elapsed time).
    desc
        Label at the start of the line.
    unit
        Name of the unit after the count (``"steps"``, ``"solves"``).
    enabled
        ``True``, ``False`` or ``None`` (automatic: only if ``stream`` is a terminal, and only
        after :data:`DELAY` seconds); see the module docstring.
    stream
        Where to draw; default ``sys.stderr`` (looked up when the bar is created).
    delay
        Seconds before the first draw; default 0 when drawing was asked for explicitly and
        :data:`DELAY` when it is automatic.
    refresh
        An active line is redrawn every ``refresh`` seconds by a background thread (the
        elapsed time moves on while one long solve runs); ``None`` or 0: only on updates.
        Call :meth:`close` (or use ``with``) to stop it.

    Attributes
    ----------
    active
        Whether this bar draws at all.
    done
        Units of work done so far.

    Examples
    --------
    >>> bar = Progress(total=None, desc="estimate", unit="solves", enabled=False)
    >>> bar.update(2, postfix="loss 3.2e-06")
    >>> bar.close()
    """

    def __init__(
        self,
        total: int | None = None,
        desc: str = "",
        *,
        unit: str = "",
        enabled: bool | None = None,
        stream: IO[str] | None = None,
        delay: float | None = None,
        refresh: float | None = REFRESH,
    ) -> None:
        self.stream = sys.stderr if stream is None else stream
        explicit = enabled if enabled is not None else _DEFAULT.get()
        self.active = is_enabled(enabled, self.stream)
        self.delay = (0.0 if explicit else DELAY) if delay is None else float(delay)
        self.total = None if total is None else max(int(total), 0)
        self.desc = desc
        self.unit = unit
        self.done = 0
        self.postfix = ""
        self.start = time.perf_counter()
        self._last_draw = -math.inf
        self._width = 0  # length of the line on screen, to blank out a longer previous one
        self._drawn = False
        self._closed = False
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self._ticker: threading.Thread | None = None
        if self.active and refresh:
            self._ticker = threading.Thread(target=self._tick, args=(float(refresh),), name="sorofem-progress",
                                            daemon=True)
            self._ticker.start()

    # -- public -------------------------------------------------------------------------

    def update(self, n: int = 1, *, postfix: str | None = None) -> None:
        """Add ``n`` units of work done (and replace the text after the count)."""
        self.set(self.done + n, postfix=postfix)

    def set(self, done: int, *, postfix: str | None = None) -> None:
        """Set the units of work done (and the text after the count)."""
        if not self.active:
            self.done = done
            if postfix is not None:
                self.postfix = postfix
            return
        with self._lock:
            self.done = done
            if postfix is not None:
                self.postfix = postfix
            self._maybe_draw()

    def refresh(self) -> None:
        """Redraw now if due (elapsed time moves on while the work is in one long call)."""
        if self.active:
            with self._lock:
                self._maybe_draw()

    def print(self, text: str) -> None:
        """Write a line of text above the progress line (which is redrawn below it)."""
        with self._lock:
            if not self.active or not self._drawn or self._closed:
                self._write(text + "\n")
                return
            self._write("\r" + " " * self._width + "\r" + text + "\n")
            self._width = 0
            self._draw()

    def close(self) -> None:
        """Draw the final state and end the line (only if anything was drawn)."""
        self._stop.set()
        if self._ticker is not None and self._ticker is not threading.current_thread():
            self._ticker.join()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if self.active and self._drawn:
                self._draw()
                self._write("\n")

    @property
    def elapsed(self) -> float:
        return time.perf_counter() - self.start

    def line(self, width: int | None = None) -> str:
        """The text of the line as it would be drawn now, at most ``width - 1`` characters."""
        if width is None:
            width = shutil.get_terminal_size(fallback=(80, 24)).columns
        elapsed = self.elapsed
        head = f"{self.desc} " if self.desc else ""
        unit = f" {self.unit}" if self.unit else ""
        tail = f"  {self.postfix}" if self.postfix else ""
        if self.total:
            fraction = min(max(self.done / self.total, 0.0), 1.0)
            if self.done >= self.total:
                eta = 0.0
            elif self.done > 0:
                eta = elapsed / self.done * (self.total - self.done)
            else:
                eta = math.nan
            percent = f"{100 * fraction:3.0f}%"
            count = f" {self.done}/{self.total}{unit} [{format_duration(elapsed)}<{format_duration(eta)}]"
            room = width - 1 - len(head) - len(percent) - len(count) - len(tail) - 2
            size = max(min(room, 30), 5)
            filled = int(size * fraction)
            text = f"{head}{percent}|{'#' * filled}{'-' * (size - filled)}|{count}{tail}"
        else:
            text = f"{head}{self.done}{unit} [{format_duration(elapsed)}]{tail}"
        return text[: max(width - 1, 1)]

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

    # -- drawing ------------------------------------------------------------------------

    def _tick(self, interval: float) -> None:
        while not self._stop.wait(interval):
            self.refresh()

    def _maybe_draw(self) -> None:
        if self._closed:
            return
        now = time.perf_counter()
        if now - self.start < self.delay:
            return
        finished = self.total is not None and self.done >= self.total
        if now - self._last_draw < MIN_INTERVAL and not finished:
            return
        self._draw()

    def _draw(self) -> None:
        text = self.line()
        pad = " " * max(self._width - len(text), 0)
        self._width = len(text)
        self._last_draw = time.perf_counter()
        self._drawn = True
        self._write("\r" + text + pad)

    def _write(self, text: str) -> None:
        try:
            self.stream.write(text)
            self.stream.flush()
        except (OSError, ValueError, AttributeError):  # closed or broken stream: stop drawing
            self.active = False

