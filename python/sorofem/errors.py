"""Exception hierarchy of sorofem.

Every error that sorofem raises on purpose is a :class:`SorofemError`. Bad input
(shapes, meshes, parameters, scene files) is an :class:`InputError`, which is also a
:class:`ValueError`; a solver that could not do its job raises a :class:`SolverError`,
which is also a :class:`RuntimeError`. The Rust extension ``sorofem._core`` imports
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
