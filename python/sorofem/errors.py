"""Exception hierarchy of sorofem.

Every error that sorofem raises on purpose is a :class:`SorofemError`. Bad input
(shapes, meshes, parameters, scene files) is an :class:`InputError`, which is also a
:class:`ValueError`; a solver that could not do its job raises a :class:`SolverError`,
which is also a :class:`RuntimeError`. A file that cannot be written (disk full, file-size limit,
no permission) is an :class:`OutputError`; a run stopped by Ctrl-C (or, on the command line,
SIGTERM) raises :class:`Interrupted`, a :class:`KeyboardInterrupt` carrying what was done. The
Rust extension ``sorofem._core`` imports
these very classes and raises them, so ``except sorofem.MeshError`` catches errors from
both sides.

Examples
--------
>>> import sorofem as sf
>>> try:
...     sf.NeoHookean(youngs_modulus=66e3, poisson_ratio=0.5)
... except sf.ParameterError as err:
...     print(err.parameter)
poisson_ratio
"""

from __future__ import annotations

from os import PathLike
from typing import Any

__all__ = [
    "SorofemError",
    "InputError",
    "ShapeError",
    "MeshError",
    "ParameterError",
    "SceneError",
    "SolverError",
    "ConvergenceError",
    "OutputError",
    "Interrupted",
]


class SorofemError(Exception):
    """Base class of all errors raised by sorofem."""


class InputError(SorofemError, ValueError):
    """Invalid input given by the user (a value, an array, a file)."""


class ShapeError(InputError):
    """An array has the wrong shape or dtype. The message names the parameter,
    the expected shape and the given one."""


class MeshError(InputError):
    """A mesh is malformed: non-finite coordinates, indices out of range,
    degenerate or (with ``orientation="reject"``) inverted tetrahedra, or a mesh
    file that cannot be parsed."""


class ParameterError(InputError):
    """A physical or numerical parameter is out of its valid range.

    Parameters
    ----------
    message
        What is wrong and what is expected.
    parameter
        Name of the offending parameter, if known (``None`` when raised by the
        extension, which names it in the message instead).
    """

    def __init__(self, message: str = "", parameter: str | None = None) -> None:
        super().__init__(message)
        self.parameter = parameter


class SceneError(InputError):
    """A scene file is invalid.

    Parameters
    ----------
    message
        What is wrong and what is expected.
    path
        The scene file.
    key
        Dotted key of the offending entry, e.g. ``"material.poisson_ratio"`` or
        ``"fixed[0].box.min"``.
    line
        1-based line number in the scene file, when it could be found.
    """

    def __init__(
        self,
        message: str = "",
        *,
        path: str | PathLike[str] | None = None,
        key: str | None = None,
        line: int | None = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.path = path
        self.key = key
        self.line = line

    def __str__(self) -> str:
        where = []
        if self.path is not None:
            where.append(str(self.path) + (f":{self.line}" if self.line is not None else ""))
        if self.key is not None:
            where.append(f"key '{self.key}'")
        return (", ".join(where) + ": " if where else "") + self.message


class SolverError(SorofemError, RuntimeError):
    """The solver failed (singular system, non-finite values, ...)."""


class ConvergenceError(SolverError):
    """Newton's method did not converge.

    Attributes
    ----------
    report
        What the solver did before giving up: a :class:`sorofem.SolveReport` when
        raised through :func:`sorofem.solve_static`, or the raw ``dict`` set by the
        extension. ``None`` if unknown.
    """

    def __init__(self, message: str = "", report: Any = None) -> None:
        super().__init__(message)
        # The extension constructs the error from the message alone and sets
        # `report` afterwards, so it must stay a plain settable attribute.
        self.report = report


class OutputError(SorofemError, OSError):
    """An output file could not be written: no space left on the device, a file-size limit,
    no permission, a read-only file system, or a folder where the file should go.

    The message names the file and the reason. Nothing half-written is left under that
    name: sorofem writes every output to a temporary file in the same folder and renames it
    over the name only once it is complete (:func:`sorofem.io.atomic_path`), so the name
    keeps its previous content (or stays absent).

    Attributes
    ----------
    path
        The file that could not be written.
    """

    def __init__(self, message: str = "", path: str | PathLike[str] | None = None, errno: int | None = None) -> None:
        super().__init__(message)
        self.path = path
        self.errno = errno

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else ""


class Interrupted(KeyboardInterrupt):
    """A run was stopped by Ctrl-C (SIGINT) or, on the command line, SIGTERM, between two
    steps of its work (a solve of the compiled core between two Newton iterations). It is a
    :class:`KeyboardInterrupt`, so code that does not know it stops as before.

    Attributes
    ----------
    result
        What was finished before the interruption, when the function can say (a partial
        :class:`sorofem.Trajectory` of the frames saved so far, the equilibria of
        :func:`sorofem.actuate` reached so far), else ``None``.
    signal
        ``"SIGINT"`` or ``"SIGTERM"``.
    report
        What the interrupted solve did until then (a :class:`sorofem.SolveReport` when raised
        through :func:`sorofem.solve_static`, the raw ``dict`` set by the extension), or
        ``None``.
    """

    def __init__(self, message: str = "interrupted", result: Any = None, signal: str = "SIGINT") -> None:
        super().__init__(message)
        self.result = result
        self.signal = signal
        # Set by the extension after construction, as ConvergenceError.report.
        self.report: Any = None
