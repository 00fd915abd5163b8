"""Progress bars for long runs (static solves, time integration, inverse problems), drawn by
`rich <https://rich.readthedocs.io>`_.

:func:`sorofem.solve_static`, :func:`sorofem.simulate`, :func:`sorofem.estimate` and
:func:`sorofem.control` take ``progress=``:

* ``None`` (default): automatic. On a terminal, or in a Jupyter notebook (rich's widget, which
  needs ``ipywidgets``), a bar appears once the run has lasted :data:`DELAY` seconds, so quick
  calls print nothing; in a pipe, a file or a CI log nothing is written.
* ``True``: always, from the start. On a terminal or in Jupyter the bar is redrawn in place;
  in a pipe, a file or a CI log its final state is written once, as one line.
* ``False``: never.

:func:`default` changes what ``progress=None`` means within a ``with`` block, for a caller
that knows better, e.g. a command line with ``--quiet``.

Examples
--------
>>> from sorofem.progress import Progress
>>> with Progress(total=3, desc="work", unit="steps", enabled=False) as bar:  # silent
...     for _ in range(3):
...         bar.update(1, postfix="loss 1e-3 m^2")
>>> bar.done
3
"""

from __future__ import annotations

import sys
import threading
from contextlib import contextmanager
from contextvars import ContextVar
from typing import IO, Any, Iterator

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    ProgressColumn,
    TaskProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress
from rich.table import Column

__all__ = ["Progress", "DELAY", "default", "is_enabled"]

#: Seconds an automatic (``progress=None``) bar waits before it first appears.
DELAY = 0.5
#: Width of the line written once to a stream that is not a terminal (a log keeps it whole).
LOG_WIDTH = 1000

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


def _interactive(stream: Any) -> bool:
    """A terminal, or a Jupyter kernel (where rich draws a widget whatever the stream)."""
    try:
        if stream.isatty():
            return True
    except (AttributeError, OSError, ValueError):
        pass
    return Console(file=stream).is_jupyter


def is_enabled(progress: bool | None, stream: Any = None) -> bool:
    """Whether a bar would be drawn on ``stream`` (default ``sys.stderr``)."""
    if progress is None:
        progress = _DEFAULT.get()
    if progress is None:
        return _interactive(sys.stderr if stream is None else stream)
    return bool(progress)


class _Guarded:
    """A stream whose write errors (a closed pipe, a reader gone) end the drawing instead of
    raising in rich's refresh thread."""

    def __init__(self, stream: Any) -> None:
        self.stream = stream
        self.broken = False

    def write(self, text: str) -> int:
        if not self.broken:
            try:
                self.stream.write(text)
            except (OSError, ValueError, AttributeError):
                self.broken = True
        return len(text)

    def flush(self) -> None:
        if not self.broken:
            try:
                self.stream.flush()
            except (OSError, ValueError, AttributeError):
                self.broken = True

    def isatty(self) -> bool:
        try:
            return bool(self.stream.isatty())
        except (AttributeError, OSError, ValueError):
            return False

    def fileno(self) -> int:
        return self.stream.fileno()


class Progress:
    """One progress bar on ``stream``, with a count, the elapsed time and, when the total is
    known, the time left; ``postfix`` is free text after it (values with their units).

    Parameters
    ----------
    total
        Number of units of work, or ``None`` when unknown (a pulsing bar, no time left).
    desc
        Label at the start of the line.
    unit
        Name of the unit after the count (``"steps"``, ``"solves"``).
    enabled
        ``True``, ``False`` or ``None`` (automatic); see the module docstring.
    stream
        Where to draw; default ``sys.stderr`` (looked up when the bar is created).
    delay
        Seconds before the bar appears; default 0 when it was asked for explicitly and
        :data:`DELAY` when it is automatic.

    Attributes
    ----------
    active
        Whether this bar draws at all.
    done
        Units of work done so far.
    postfix
        The text after the count.
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
    ) -> None:
        self.stream = sys.stderr if stream is None else stream
        explicit = enabled if enabled is not None else _DEFAULT.get()
        self.active = is_enabled(enabled, self.stream)
        self.delay = (0.0 if explicit else DELAY) if delay is None else float(delay)
        self.total = None if total is None else max(int(total), 0)
        self.done = 0
        self.postfix = ""
        self._desc = desc
        self._lock = threading.RLock()
        self._shown = False
        self._closed = False
        self._timer: threading.Timer | None = None
        self._bar: RichProgress | None = None
        if not self.active:
            return
        interactive = _interactive(self.stream)
        self._out = _Guarded(self.stream)
        console = Console(file=self._out, width=None if interactive else LOG_WIDTH, highlight=False)
        # A bar and the time left only when the total is known; otherwise a count and the clock.
        columns: list[ProgressColumn | str] = [TextColumn("{task.description}", markup=False)]
        if self.total is not None:
            columns += [BarColumn(), TaskProgressColumn(), MofNCompleteColumn()]
        else:
            columns.append(TextColumn("{task.completed}", markup=False))
        columns += [TextColumn("{task.fields[unit]}", markup=False), TimeElapsedColumn()]
        if self.total is not None:
            columns.append(TimeRemainingColumn())
        # A narrow terminal wraps the postfix onto a second line rather than cutting it; a log
        # keeps the line whole.
        tail = Column(overflow="fold") if interactive else Column(no_wrap=True, overflow="ignore")
        columns.append(TextColumn("{task.fields[postfix]}", markup=False, table_column=tail))
        self._bar = RichProgress(*columns, console=console, redirect_stdout=False, redirect_stderr=False)
        self._task = self._bar.add_task(desc, total=self.total, unit=unit, postfix="")
        if self.delay > 0:
            self._timer = threading.Timer(self.delay, self._show)
            self._timer.daemon = True
            self._timer.start()
        else:
            self._show()

    @property
    def desc(self) -> str:
        """The label at the start of the line (may be changed while the bar runs)."""
        return self._desc

    @desc.setter
    def desc(self, text: str) -> None:
        self._desc = text
        if self._bar is not None:
            self._bar.update(self._task, description=text)

    def update(self, n: int = 1, *, postfix: str | None = None) -> None:
        """Add ``n`` units of work done (and replace the text after the count)."""
        self.set(self.done + n, postfix=postfix)

    def set(self, done: int, *, postfix: str | None = None) -> None:
        """Set the units of work done (and the text after the count)."""
        self.done = done
        if postfix is not None:
            self.postfix = postfix
        if self._bar is not None:
            self._bar.update(self._task, completed=done, postfix=self.postfix)

    def print(self, text: str) -> None:
        """Write a line of text above the bar (or as a plain line when no bar is shown)."""
        with self._lock:
            if self._bar is not None and self._shown and not self._closed:
                self._bar.console.print(text, markup=False, highlight=False, soft_wrap=True)
                return
        out = _Guarded(self.stream)
        out.write(text + "\n")
        out.flush()

    def close(self) -> None:
        """Stop the bar, leaving its final state on screen (if it was shown at all)."""
        if self._timer is not None:
            self._timer.cancel()
        with self._lock:
            if self._closed:
                return
            self._closed = True
            if self._bar is not None and self._shown:
                self._bar.stop()

    def _show(self) -> None:
        with self._lock:
            if self._closed or self._bar is None:
                return
            self._bar.start()
            self._shown = True

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
