"""Checks of user input shared by every module: each message names the parameter, what was
expected and what was given, so a user can act on it without reading the source.

Internal: the public functions and classes call these and document the errors they raise.
"""

from __future__ import annotations

import math
import numbers
import os
import sys
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError, ParameterError, ShapeError

__all__ = [
    "LIMITS",
    "Limit",
    "MAX_NEWTON_ITERATIONS",
    "MAX_LOAD_STEPS",
    "MAX_CUTBACKS",
    "MAX_TIME_STEPS",
    "MAX_CABLE_DIVISIONS",
    "MAX_STARTS",
    "MAX_EVALUATIONS",
    "MAX_INDEX",
    "MESH_SIZE",
    "MAX_MAGNITUDE",
    "machine_memory",
    "check_memory",
    "count",
    "Range",
    "describe",
    "shown",
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


@dataclass(frozen=True)
class Limit:
    """A documented bound on an input: ``name`` (the argument or scene key it bounds), its
    ``value`` and why it is there (``why``)."""

    name: str
    value: float
    why: str


#: Newton iterations per load step (``max_iterations``, ``[solver] max_iterations``).
MAX_NEWTON_ITERATIONS = 10_000
#: Load increments of a static solve (``load_steps``).
MAX_LOAD_STEPS = 10_000
#: Halvings of a failed load step (``[solver] max_cutbacks``): 2^-60 of a step is below
#: float64's resolution of the load factor.
MAX_CUTBACKS = 60
#: Time steps of one simulation (``steps``, ``[dynamics] steps``); also bounds ``save_every``.
MAX_TIME_STEPS = 1_000_000
#: Segments of a straight cable (``Cable.line(divisions=...)``, ``[[cable]] divisions``).
MAX_CABLE_DIVISIONS = 100_000
#: Extra starts of an estimate (``starts``, ``[estimate] starts``).
MAX_STARTS = 1_000
#: Objective evaluations per start of an estimate or a control (``max_evaluations``).
MAX_EVALUATIONS = 100_000
#: Any other integer of a scene file (node, element and cable indices, box cells per axis).
MAX_INDEX = 2**31 - 1
#: Length of a mesh's bounding-box diagonal, m: ``(smallest, largest)``.
MESH_SIZE = (1e-9, 1e9)
#: Largest load (N), stiffness times mesh size (N) and simulated time (s): the solver sums
#: squares of such values in its residual norm, which must stay below float64's 1.8e308.
MAX_MAGNITUDE = 1e150

#: Every documented limit, by the name it bounds (the docs page "What sorofem guarantees"
#: lists them from here).
LIMITS: dict[str, Limit] = {
    limit.name: limit
    for limit in (
        Limit("max_iterations", MAX_NEWTON_ITERATIONS, "Newton iterations per load step; more never converge "
              "where fewer did not"),
        Limit("load_steps", MAX_LOAD_STEPS, "load increments of a static solve (the solver cuts steps back itself)"),
        Limit("max_cutbacks", MAX_CUTBACKS, "halvings of a failed load step: a 2^-60 step is below the resolution "
              "of the load factor"),
        Limit("steps", MAX_TIME_STEPS, "time steps of one simulation (save_every is bounded by it too): a longer "
              "run is several runs, each continuing the last (initial=trajectory)"),
        Limit("divisions", MAX_CABLE_DIVISIONS, "segments of a straight cable"),
        Limit("starts", MAX_STARTS, "extra starts of an estimate"),
        Limit("max_evaluations", MAX_EVALUATIONS, "objective evaluations per start of an estimate or control"),
        Limit("index", MAX_INDEX, "any other integer in a scene file: node, element and cable indices, box cells "
              "per axis"),
        Limit("mesh size", MESH_SIZE[1], f"bounding-box diagonal of a mesh, m, from {MESH_SIZE[0]:g} to "
              f"{MESH_SIZE[1]:g}: beyond, volumes and stiffnesses leave the range of float64"),
        Limit("magnitude", MAX_MAGNITUDE, "total load (N: forces, weight), stiffness times mesh size (N: "
              "moduli, cable stiffness), stiffness times prescribed displacement (N) and simulated time dt * steps "
              "(s): beyond, squares in the residual norm overflow float64"),
        Limit("memory", 1.0, "a model whose estimated memory exceeds the machine's (physical memory, or the "
              "cgroup's limit) is refused before anything is allocated"),
    )
}


def machine_memory() -> int:
    """Bytes of memory this process may use: the physical memory, or the cgroup's limit when
    lower (a container)."""
    try:
        total = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (ValueError, OSError, AttributeError):
        total = 2**62
    for limit_file in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            with open(limit_file, encoding="ascii") as fh:
                text = fh.read().strip()
        except OSError:
            continue
        if text.isdigit():
            total = min(total, int(text))
    return int(total)


def _gib(n_bytes: float) -> str:
    return f"{n_bytes / 2**30:.3g} GiB"


def check_memory(n_bytes: float, what: str, name: str) -> None:
    """A :class:`ParameterError` naming ``name`` when ``what`` needs more than
    :func:`machine_memory` (``n_bytes`` is an estimate, a lower bound)."""
    available = machine_memory()
    if n_bytes > available:
        raise ParameterError(
            f"{name}: {what} needs at least {_gib(n_bytes)} of memory, more than this machine has "
            f"({_gib(available)}); use a coarser mesh",
            name,
        )


def count(value: Any, name: str, minimum: int, maximum: int) -> int:
    """An integer in ``[minimum, maximum]`` (a :class:`ParameterError` naming ``name`` and the
    bound otherwise); NumPy integers too, never a bool or a float."""
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Integral):
        raise ParameterError(f"{name}: expected an integer from {minimum} to {maximum}, got {describe(value)}", name)
    value = int(value)
    if not minimum <= value <= maximum:
        limit = " (the documented limit, see sorofem's guarantees)" if value > maximum else ""
        raise ParameterError(f"{name}: expected an integer from {minimum} to {maximum}{limit}, got {shown(value)}", name)
    return value


def dask_client(value: Any, name: str = "client") -> Any:
    """``value`` if it is a ``dask.distributed.Client`` (a :class:`ParameterError` naming
    ``name`` otherwise: anything else would fail later with an ``AttributeError``). A client
    exists only once ``distributed`` is imported, so it is not imported here (it is an extra)."""
    distributed = sys.modules.get("distributed")
    if distributed is None or not isinstance(value, distributed.Client):
        raise ParameterError(f"{name}: expected a dask.distributed.Client, got {describe(value)}", name)
    return value


def describe(value: Any) -> str:
    """A value for an error message: ``an array of shape (3,) and dtype int64``, ``str 'abc'``."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} and dtype {value.dtype}"
    return f"{type(value).__name__} {shown(value)}"


def shown(value: Any, width: int = 80) -> str:
    """``repr(value)`` cut to ``width`` characters; an integer too long to print (Python refuses
    more than 4300 digits) by its size."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 256:
        return f"<an integer of {value.bit_length()} bits>"
    try:
        text = repr(value)
    except Exception:  # noqa: BLE001 - a user object whose repr fails
        text = f"<{type(value).__name__} object>"
    return text if len(text) <= width else text[: width - 3] + "..."


def _array(value: Any, name: str, what: str) -> NDArray[Any]:
    """``np.asarray(value)``; ragged nesting, integers beyond 64 bits and other values NumPy
    cannot hold as a regular array become a :class:`ShapeError` naming ``name``."""
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError, OverflowError):
        raise ShapeError(f"{name}: expected {what}, got {describe(value)}") from None
    if arr.dtype == object:
        raise ShapeError(f"{name}: expected {what}, got {describe(value)}")
    return arr


def as_float_array(value: ArrayLike, name: str, shape: tuple[int | None, ...]) -> NDArray[np.float64]:
    """A C-contiguous float64 array of the given shape (``None``: any length).

    Raises
    ------
    ShapeError
        Not a real numeric array, or another shape.
    """
    try:
        arr = np.asarray(value)
    except (TypeError, ValueError, OverflowError) as exc:
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
    arr = _array(value, name, "node indices")
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
    arr = _array(value, name, "a (3,) vector or a (k, 3) array")
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


def positive_int(value: Any, name: str, maximum: int | None = None) -> int:
    """An integer >= 1, and <= ``maximum`` when given (a :class:`ParameterError` naming
    ``name`` otherwise)."""
    if maximum is not None:
        return count(value, name, 1, maximum)
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
