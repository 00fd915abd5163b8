"""Checks of user input shared by every module: each message names the parameter, what was
expected and what was given, so a user can act on it without reading the source.

Internal: the public functions and classes call these and document the errors they raise.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError, ParameterError, ShapeError

__all__ = [
    "Range",
    "describe",
    "as_float_array",
    "as_finite",
    "as_index_array",
    "vector_per_node",
    "positive_scalar",
    "positive_int",
    "real",
    "non_negative",
    "boolean",
    "choice",
]


def describe(value: Any) -> str:
    """A value for an error message: ``an array of shape (3,) and dtype int64``, ``str 'abc'``."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    return f"{type(value).__name__} {value!r}"


def as_float_array(value: ArrayLike, name: str, shape: tuple[int | None, ...]) -> NDArray[np.float64]:
    """A C-contiguous float64 array of the given shape (``None``: any length).

    Raises
    ------
    ShapeError
        Not a real numeric array, or another shape.
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError) as exc:
        raise ShapeError(f"{name}: expected a numeric array, got {describe(value)} ({exc})") from None
    if arr.dtype == object or not (
        np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)
    ) or arr.dtype == np.bool_:
        raise ShapeError(f"{name}: expected a real numeric array, got {describe(arr)}")
    if arr.ndim != len(shape) or any(s is not None and s != a for s, a in zip(shape, arr.shape)):
        expected = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ("," if len(shape) == 1 else "") + ")"
        raise ShapeError(f"{name}: expected shape {expected}, got shape {arr.shape}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def as_finite(value: ArrayLike, name: str, shape: tuple[int | None, ...]) -> NDArray[np.float64]:
    """:func:`as_float_array`, and every entry finite (an :class:`InputError` otherwise)."""
    arr = as_float_array(value, name, shape)
    if not np.all(np.isfinite(arr)):
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(f"{name}: expected finite values, got {arr[tuple(bad)]} at index {tuple(int(i) for i in bad)}")
    return arr


def as_index_array(value: ArrayLike, name: str, n_nodes: int) -> NDArray[np.int64]:
    """Node indices as a 1-D int64 array in ``[0, n_nodes)``; a boolean mask of length
    ``n_nodes`` is accepted too."""
    arr = np.asarray(value)
    if arr.dtype == np.bool_:
        if arr.shape != (n_nodes,):
            raise ShapeError(f"{name}: a boolean mask must have shape ({n_nodes},), got shape {arr.shape}")
        return np.flatnonzero(arr).astype(np.int64)
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.size == 0:
        return np.zeros(0, dtype=np.int64)
    if not np.issubdtype(arr.dtype, np.integer):
        raise ShapeError(f"{name}: expected integer node indices, got {describe(arr)}")
    if arr.ndim != 1:
        raise ShapeError(f"{name}: expected a 1-D array of node indices, got shape {arr.shape}")
    arr = arr.astype(np.int64)
    bad = (arr < 0) | (arr >= n_nodes)
    if np.any(bad):
        raise InputError(
            f"{name}: node indices must be in [0, {n_nodes}), got {int(arr[bad][0])} "
            f"({int(bad.sum())} out of range)"
        )
    return arr


def vector_per_node(value: ArrayLike, name: str, k: int) -> NDArray[np.float64]:
    """A ``(3,)`` vector broadcast to ``k`` nodes, or a ``(k, 3)`` array; finite."""
    arr = np.asarray(value)
    if arr.ndim == 1:
        vec = as_finite(arr, name, (3,))
        return np.broadcast_to(vec, (k, 3)).copy()
    return as_finite(arr, name, (k, 3))


def _is_real(value: Any) -> bool:
    return not isinstance(value, bool) and isinstance(value, numbers.Real)


def positive_scalar(value: Any, name: str) -> float:
    """A finite number > 0, as float (a :class:`ParameterError` naming ``name`` otherwise)."""
    if not _is_real(value):
        raise ParameterError(f"{name}: expected a positive number, got {describe(value)}", name)
    value = float(value)
    if not (math.isfinite(value) and value > 0):
        raise ParameterError(f"{name}: expected a finite positive number, got {value}", name)
    return value


def positive_int(value: Any, name: str) -> int:
    """An integer >= 1 (a :class:`ParameterError` naming ``name`` otherwise)."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
        raise ParameterError(f"{name}: expected an integer >= 1, got {describe(value)}", name)
    return int(value)


def real(value: Any, name: str, *, minimum: float, strict: bool, maximum: float | None = None) -> float:
    """A finite number above ``minimum`` (strictly or not) and below ``maximum`` (strictly)."""
    if not _is_real(value):
        raise ParameterError(f"{name}: expected a number, got {describe(value)}", name)
    value = float(value)
    below = value <= minimum if strict else value < minimum
    if not math.isfinite(value) or below or (maximum is not None and value >= maximum):
        lo = f"{'>' if strict else '>='} {minimum:g}"
        hi = f" and < {maximum:g}" if maximum is not None else ""
        raise ParameterError(f"{name}: expected a finite number {lo}{hi}, got {value}", name)
    return value


def non_negative(value: Any, name: str) -> float:
    """A finite number >= 0, as float."""
    if not _is_real(value) or not (math.isfinite(float(value)) and float(value) >= 0):
        raise ParameterError(f"{name}: expected a finite number >= 0, got {describe(value)}", name)
    return float(value)


def boolean(value: Any, name: str) -> bool:
    """True or False (NumPy's too), as bool."""
    if not isinstance(value, (bool, np.bool_)):
        raise ParameterError(f"{name}: expected True or False, got {describe(value)}", name)
    return bool(value)


def choice(value: Any, name: str, allowed: Sequence[str], error: type[InputError] = InputError) -> str:
    """One of the strings ``allowed``; ``error`` (an :class:`InputError` by default) otherwise."""
    if not isinstance(value, str) or value not in allowed:
        message = f"{name}: expected one of {list(allowed)}, got {value!r}"
        raise error(message, name) if issubclass(error, ParameterError) else error(message)
    return value


@dataclass(frozen=True)
class Range:
    """Valid values of a parameter: a lower bound (``gt`` or ``ge``) and an upper bound (``lt``),
    each optional, with the reason for each bound (``low_note``, ``high_note``) that error
    messages give.

    Examples
    --------
    >>> from sorofem.materials import Range
    >>> Range(ge=0, lt=0.5).describe()
    '>= 0 and < 0.5'
    """

    gt: float | None = None
    ge: float | None = None
    lt: float | None = None
    low_note: str = ""
    high_note: str = ""

    def bounds(self) -> list[tuple[str, float, str]]:
        """``(operator, value, note)`` of each bound, lower first."""
        out = [(op, v, self.low_note) for op, v in ((">", self.gt), (">=", self.ge)) if v is not None]
        if self.lt is not None:
            out.append(("<", self.lt, self.high_note))
        return out

    def describe(self) -> str:
        """``"> 0"``, ``">= 0 and < 0.5"``, or ``""`` (any value)."""
        return " and ".join(f"{op} {v:g}" for op, v, _ in self.bounds())

    def contains(self, values: ArrayLike) -> NDArray[np.bool_]:
        """Elementwise whether ``values`` are in the range (NaN is not)."""
        x = np.asarray(values, dtype=np.float64)
        ok = np.ones(x.shape, dtype=bool)
        for op, v, _ in self.bounds():
            ok &= _OPERATORS[op](x, v)
        return ok

    def violated(self, values: ArrayLike) -> tuple[str, float, str] | None:
        """The first bound ``(operator, value, note)`` that some of ``values`` break, or None."""
        x = np.asarray(values, dtype=np.float64)
        for op, v, note in self.bounds():
            if not np.all(_OPERATORS[op](x, v)):
                return op, v, note
        return None

    def check(self, values: ArrayLike, name: str, symbol: str = "", units: str = "") -> None:
        """Raise a :class:`ParameterError` naming ``name`` when any value is out of range: the
        message gives the bound that fails, its reason and the first offending value."""
        bound = self.violated(values)
        if bound is None:
            return
        op, v, note = bound
        x = np.asarray(values, dtype=np.float64)
        ok = _OPERATORS[op](x, v)
        shown = float(x) if x.ndim == 0 else f"{x[~ok][0]} (per-element)"
        expected = " ".join(filter(None, (symbol, op, f"{v:g}", units)))
        reason = f" ({note})" if note else ""
        raise ParameterError(f"{name}: expected {expected}{reason}, got {shown}", name)


_OPERATORS = {">": np.greater, ">=": np.greater_equal, "<": np.less}
