"""Solving the cases of a sweep, where they run (a Dask worker, or this process): each case is
the scene with its overrides, solved by :meth:`Scene.solve` (or :meth:`Scene.simulate` with
``[dynamics]``) as ``sorofem run`` solves it, and summarised as one row of the results table.

A worker keeps the scenes it built, by structure (:func:`sorofem.scene.structure_key`): the
cases of a batch, and of later batches that share a mesh, supports and cables, are built
``like`` them and solve with the same compiled model (the symbolic factorisation is done once
per worker, not once per case).
"""

from __future__ import annotations

import functools
import math
import time
import tomllib
import traceback
from collections import OrderedDict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import InputError, SolverError
from ..progress import default as progress_default
from ..scene import Scene
from ..targets import embed_points
from ._cases import Key, parse_key

__all__ = ["Batch", "Outcome", "solve_batch", "tip_node", "FIELDS", "clear_cache"]

#: Full fields a sweep can save per case (``save=``), as ``(n_nodes, 3)`` arrays.
FIELDS = ("displacement",)
#: Scenes a worker keeps (by structure), least recently used dropped first.
CACHE_SIZE = 4


@dataclass
class _Kept:
    """A scene kept by a worker, with what every case of its structure shares: the tip node and
    where the markers lie (tetrahedron, barycentric weights)."""

    scene: Scene
    tip: int
    markers: dict[tuple[tuple[float, float, float], ...], tuple[NDArray[np.int64], NDArray[np.float64]]] = field(
        default_factory=dict)


_CACHE: "OrderedDict[tuple[str, str, str], _Kept]" = OrderedDict()


@dataclass(frozen=True)
class Batch:
    """What a worker needs to solve some cases of a sweep (plain data: it is sent over the wire)."""

    #: The scene file's path (errors name it; relative mesh files are found from its folder) and text.
    scene_path: str
    scene_text: str
    keys: tuple[str, ...]
    #: ``(case id, values in the order of keys)``.
    cases: tuple[tuple[int, tuple[Any, ...]], ...]
    #: Rest points ``(k, 3)`` whose deformed positions are collected, m.
    markers: tuple[tuple[float, float, float], ...] = ()
    save: tuple[str, ...] = ()
    #: Number of cables of the scene (one tension column each).
    n_cables: int = 0


@dataclass
class Outcome:
    """One solved (or failed) case: its row and the fields asked for."""

    case: int
    row: dict[str, Any]
    fields: dict[str, NDArray[np.float64]] = field(default_factory=dict)


def clear_cache() -> None:
    """Forget the scenes this process keeps (their compiled models are freed)."""
    _CACHE.clear()
    _parsed.cache_clear()


@functools.lru_cache(maxsize=CACHE_SIZE)
def _parsed(scene_text: str, keys: tuple[str, ...]) -> tuple[tuple[Key, ...], dict[str, Any]]:
    """The keys and the scene's tables of a sweep, read once per process rather than once per
    batch (the keys' checks walk the scene spec: about a millisecond a batch). The tables are
    shared by every case: :meth:`Key.apply` copies what it changes."""
    return tuple(parse_key(text) for text in keys), tomllib.loads(scene_text)


def tip_node(scene: Scene) -> int:
    """The node farthest from the supports (the lowest index among equals): the tip of a
    cantilever, the default point a sweep follows."""
    from scipy.spatial import cKDTree

    fixed = scene.body.fixed_nodes
    if fixed.size == 0:
        return 0
    distance, _ = cKDTree(scene.mesh.points[fixed]).query(scene.mesh.points)
    return int(np.argmax(distance))


def _scene(batch: Batch, keys: tuple[Key, ...], values: tuple[Any, ...], base: dict[str, Any]) -> tuple[Scene, _Kept]:
    """The case's scene, built like a kept scene of the same structure when there is one."""
    data = base
    for key, value in zip(keys, values):
        data = key.apply(data, value, "case")
    scene = Scene.from_data(data, Path(batch.scene_path), text=batch.scene_text,
                            like=[kept.scene for kept in _CACHE.values()])
    entry = (batch.scene_path, batch.scene_text, scene.structure)
    if entry in _CACHE:
        _CACHE.move_to_end(entry)
    else:
        _CACHE[entry] = _Kept(scene, tip_node(scene))
        while len(_CACHE) > CACHE_SIZE:
            _CACHE.popitem(last=False)
    return scene, _CACHE[entry]


def _positions(batch: Batch, kept: _Kept, positions: NDArray[np.float64], row: dict[str, Any]) -> None:
    row["tip.node"] = kept.tip
    for axis, value in zip("xyz", positions[kept.tip]):
        row[f"tip.{axis}"] = float(value)
    if batch.markers:
        if batch.markers not in kept.markers:
            kept.markers[batch.markers] = embed_points(kept.scene.mesh, np.array(batch.markers))
        tets, weights = kept.markers[batch.markers]
        at = np.einsum("kj,kjd->kd", weights, positions[kept.scene.mesh.tets[tets]])
        for i, point in enumerate(at):
            for axis, value in zip("xyz", point):
                row[f"marker[{i}].{axis}"] = float(value)


def _solve_case(batch: Batch, scene: Scene, kept: _Kept, row: dict[str, Any]) -> dict[str, NDArray[np.float64]]:
    """Solve as ``sorofem run`` does; fills the row (the values of ``summary.json`` it names),
    returns the fields to save."""
    start = time.perf_counter()
    if scene.dynamics is None:
        result = scene.solve()
        row["time"] = time.perf_counter() - start
        row["newton_iterations"] = result.report.iterations
        row["residual_norm"] = result.report.residual_norm
        row["max_displacement"] = result.max_displacement
        positions, tensions, displacement = result.positions, result.cable_tensions, result.displacement
    else:
        trajectory = scene.simulate(progress=False)
        row["time"] = time.perf_counter() - start
        summary = trajectory.to_dict()
        for name in ("newton_iterations", "max_displacement", "steps", "cutbacks", "final_time",
                     "final_kinetic_energy"):
            row[name] = summary[name]
        positions, tensions = trajectory.final_positions, trajectory.cable_tensions(-1)
        displacement = trajectory.displacement[-1]
    row["converged"] = True
    _positions(batch, kept, positions, row)
    for c, t in enumerate(tensions):
        row[f"cable[{c}].max_tension"] = float(np.max(t, initial=0.0))
        row[f"cable[{c}].tensions"] = [float(v) for v in t]
    return {"displacement": np.asarray(displacement, dtype=np.float64)} if "displacement" in batch.save else {}


def _failure(row: dict[str, Any], exc: BaseException) -> None:
    row["converged"] = False
    report = getattr(exc, "report", None)
    iterations = getattr(report, "iterations", None)
    if iterations is None and isinstance(report, dict):
        iterations = report.get("iterations")
    residual = getattr(report, "residual_norm", None)
    row["newton_iterations"] = None if iterations is None else int(iterations)
    row["residual_norm"] = None if residual is None or not math.isfinite(residual) else float(residual)
    message = " ".join(str(exc).split()) or type(exc).__name__
    if isinstance(exc, InputError):
        message = f"bad input: {message}"
    elif not isinstance(exc, SolverError):
        message = f"unexpected {type(exc).__name__}: {message} ({traceback.format_exc(limit=-1).strip()})"
    row["error"] = message


def solve_batch(batch: Batch) -> list[Outcome]:
    """Solve the cases of a batch in turn; a case that fails (no convergence, a bad value the
    spec could not see) is a row with ``converged = False`` and its ``error``.

    Runs on a Dask worker (any process: the batch is plain data). Progress lines of the solves
    are switched off: only the sweep draws one.
    """
    keys, base = _parsed(batch.scene_text, batch.keys)
    out = []
    with progress_default(False):
        for case, values in batch.cases:
            row: dict[str, Any] = {"case": case, "error": None}
            fields: dict[str, NDArray[np.float64]] = {}
            try:
                scene, kept = _scene(batch, keys, values, base)
                fields = _solve_case(batch, scene, kept, row)
            except Exception as exc:  # noqa: BLE001 - every failure of one case is its row, never a lost sweep
                _failure(row, exc)
            out.append(Outcome(case, row, fields))
    return out
