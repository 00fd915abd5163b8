"""Benchmarks behind `make bench`: run every case in a fresh process and write BENCHMARKS.md.

    python benchmarks/run.py --write BENCHMARKS.md            # all cases
    python benchmarks/run.py --write BENCHMARKS.md --quick    # small cases only
    python benchmarks/run.py --list
    python benchmarks/run.py --only 'sorofem/cantilever-0.4m-*'

Each case is one function registered with :func:`case`; it runs in a child process of its own
(``run.py --child NAME``), so its peak memory is that child's ``ru_maxrss`` (taken by the parent
with ``os.wait4``) and no case warms the caches of the next. A case returns a JSON-able row and
may save arrays (``save_array``) that report sections compare across cases, e.g. sorofem's and
scikit-fem's displacements on the same mesh.

Adding a benchmark for a later issue is: one case function, registered under a table (add a
``Table`` if it needs new columns), and, if it has a target, one line in ``targets()``.

Cases run in registration order, except those registered with ``last=True`` (the scikit-fem
1 m 48x8x8 peer, ~15 minutes), which run after all others. ``--write`` rewrites only the
sections this runner owns (the preamble, its tables, the comparison, the targets and the run
log) and keeps every other ``## `` section of the file (e.g. "## Locking study", written by
examples/02_locking_study.py) as it was, after its own.
"""

from __future__ import annotations

import argparse
import datetime as dt
import fnmatch
import json
import math
import os
import platform
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path
from typing import Any, Callable

import numpy as np

BENCH_DIR = Path(__file__).resolve().parent
REPO = BENCH_DIR.parent
SOLIDFEM_DATA = REPO.parent / "shared" / "data" / "solidfem"
CASE_TIMEOUT_S = 3600.0

# ---------------------------------------------------------------------------
# Registry


@dataclass(frozen=True)
class Column:
    header: str
    format: Callable[[dict[str, Any]], str]


@dataclass(frozen=True)
class Table:
    title: str
    description: str
    columns: tuple[Column, ...]


@dataclass(frozen=True)
class Case:
    name: str
    table: str
    run: Callable[[], dict[str, Any]]
    quick: bool
    last: bool = False


TABLES: dict[str, Table] = {}
CASES: dict[str, Case] = {}


def case(
    name: str, table: str, quick: bool = False, last: bool = False
) -> Callable[[Callable[[], dict[str, Any]]], Callable]:
    """Register ``func`` (no arguments, returns a JSON-able row) as the benchmark ``name``.

    ``quick``: also run by ``--quick``. ``last``: run after every other case (slow ones).
    """

    def register(func: Callable[[], dict[str, Any]]) -> Callable:
        if name in CASES:
            raise ValueError(f"benchmark case {name!r} registered twice")
        if table not in TABLES:
            raise ValueError(f"benchmark case {name!r}: unknown table {table!r}")
        CASES[name] = Case(name, table, func, quick, last)
        return func

    return register


# ---------------------------------------------------------------------------
# Helpers for case functions (they run in the child process)

_ARRAY_DIR: Path | None = None


def save_array(key: str, value: np.ndarray) -> None:
    """Keep an array of the current case for cross-case comparisons (``load_array``)."""
    if _ARRAY_DIR is not None:
        np.save(_ARRAY_DIR / f"{_safe(_CURRENT_CASE)}--{key}.npy", np.asarray(value))


def load_array(case_name: str, key: str, array_dir: Path) -> np.ndarray | None:
    path = array_dir / f"{_safe(case_name)}--{key}.npy"
    return np.load(path) if path.exists() else None


_CURRENT_CASE = ""


def _safe(name: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", name)


def repeat_timed(
    fn: Callable[[], Any],
    budget_s: float = 2.0,
    max_repeats: int = 7,
    after: Callable[[Any], Any] | None = None,
) -> dict[str, Any]:
    """Call ``fn`` once, then again while the time spent is under ``budget_s``.

    ``after``, when given, is called (untimed) with each run's result right after it: for
    measurements that must be paired with that run (taken under the same machine state).

    Returns the wall times, the first (cold) one, the median, the result of the median run and
    the ``after`` outputs of every run.
    """
    times: list[float] = []
    results: list[Any] = []
    afterwards: list[Any] = []
    spent = 0.0
    while len(times) < max_repeats and (not times or spent + times[-1] < budget_s):
        t0 = time.perf_counter()
        results.append(fn())
        times.append(time.perf_counter() - t0)
        spent += times[-1]
        if after is not None:
            afterwards.append(after(results[-1]))
    order = sorted(range(len(times)), key=times.__getitem__)
    mid = order[(len(order) - 1) // 2]
    return {"times": times, "first": times[0], "median": times[mid], "result": results[mid], "after": afterwards}


def box_points_tets(size: tuple[float, float, float], cells: tuple[int, int, int]) -> tuple[np.ndarray, np.ndarray, str]:
    """Points and tets of the box mesh: sorofem's own when the extension is built, else the peer's copy."""
    try:
        import sorofem as sf

        mesh = sf.Mesh.box(size=size, cells=cells)
        return np.asarray(mesh.points), np.asarray(mesh.tets), "sorofem.Mesh.box"
    except ImportError:
        from peers.skfem_neohookean import box_mesh

        points, tets = box_mesh(size, cells)
        return points, tets, "peers.skfem_neohookean.box_mesh (sorofem not built)"


# ---------------------------------------------------------------------------
# Formatting


def _g(x: Any, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if isinstance(x, (int, np.integer)):
        return str(x)
    x = float(x)
    if x == 0:
        return "0"
    if abs(x) >= 10 ** digits or abs(x) < 1e-3:
        return f"{x:.{digits - 1}e}"
    return f"{x:.{digits}g}"


def _ms(x: Any) -> str:
    return "-" if x is None else f"{1e3 * float(x):.3g}"


def _col(header: str, key: str, fmt: Callable[[Any], str] = _g) -> Column:
    return Column(header, lambda r: fmt(r.get(key)))


def _phase(key: str) -> Callable[[dict[str, Any]], str]:
    return lambda r: _ms((r.get("timings") or {}).get(key))


def _status(r: dict[str, Any]) -> str:
    if r.get("error"):
        return "ERROR"
    return "yes" if r.get("converged") else "**no**"


def _mib(r: dict[str, Any]) -> str:
    return _g(r.get("peak_rss_mib"), 4)


def _per_iteration_ratio(r: dict[str, Any]) -> float | None:
    """(time per Newton iteration) / (time of one bare numeric factorisation).

    A bare factorisation is timed on its own right after each solve (median of three, nothing
    beside it: `Model.time_factorization`), not taken from the solve's own timings; the ratio is
    the median over the repeats of each solve's ratio to its own bare factorisation, so that a
    drift of the machine's speed between the solves and the bare timing does not enter it.
    Whatever else an iteration pays for (a failed factorisation and a second, projected Hessian)
    counts against it.
    """
    if r.get("per_iteration_ratios"):
        return statistics.median(r["per_iteration_ratios"])
    t = r.get("timings") or {}
    bare = r.get("bare_factorization_seconds")
    if not bare or not r.get("iterations") or not t.get("total"):
        return None
    return t["total"] / r["iterations"] / bare


def _factorization_share(r: dict[str, Any]) -> float | None:
    """Total solve time over the time of all numeric factorisations, failed ones included."""
    t = r.get("timings") or {}
    return t["total"] / t["factorization"] if t.get("factorization") else None


# ---------------------------------------------------------------------------
# Tables and cases: issue 2 (static Neo-Hookean solves)

MATERIAL = dict(youngs_modulus=66e3, poisson_ratio=0.45, density=1080.0)
GRAVITY = (0.0, 0.0, -9.81)
TOLERANCE = 1e-8

TABLES["static"] = Table(
    "Static solves (sorofem)",
    "Cantilever b x h = 0.1 x 0.1 m clamped at x = 0 under gravity (0, 0, -9.81) m/s^2, Neo-Hookean "
    "E = 66 kPa, nu = 0.45, rho = 1080 kg/m^3, one load step, tolerance 1e-8 on "
    "||r_free|| / ||f_ext_free||. Time = wall time of `Body(...)`, `fix` and `solve_static` (building "
    "the model, i.e. the symbolic analysis, included), median of the repeats; phases are the solver's "
    "own `report.timings` of that run, in ms. fact. = numeric factorisations (of which failed: the "
    "exact Hessian was indefinite and the projected one was factorised as well). bare fact. = one "
    "numeric factorisation of the Hessian at the solution timed alone right after each solve (median "
    "of three; the median over the repeats is shown); t/it / bare fact. = time per Newton "
    "iteration (report total / iterations) over it, the median over the repeats of each solve's "
    "ratio to its own bare factorisation; total / all fact. = solve time "
    "over the time of all factorisations in the solve, failed ones included. "
    "w_tip = mean z-displacement of the x = L face.",
    (
        _col("case", "case", str),
        _col("tets", "tets"),
        _col("free DOFs", "dofs"),
        Column("conv.", _status),
        _col("Newton it.", "iterations"),
        _col("time [s]", "seconds"),
        _col("first run [s]", "seconds_first"),
        _col("repeats", "repeats"),
        Column("assembly [ms]", _phase("assembly")),
        Column("factor. [ms]", _phase("factorization")),
        Column("solve [ms]", _phase("solve")),
        Column("line search [ms]", _phase("line_search")),
        Column("report total [ms]", _phase("total")),
        Column("fact. (failed)", lambda r: f"{_g(r.get('factorizations'))} ({_g(r.get('failed_factorizations'))})"),
        Column("bare fact. [ms]", lambda r: _ms(r.get("bare_factorization_seconds"))),
        Column("t/it / bare fact.", lambda r: _g(_per_iteration_ratio(r))),
        Column("total / all fact.", lambda r: _g(_factorization_share(r))),
        _col("w_tip [m]", "tip_deflection", lambda x: _g(x, 6)),
        Column("peak RSS [MiB]", _mib),
    ),
)

def _mm3(key: str) -> Callable[[dict[str, Any]], str]:
    """A 3-vector in metres, shown in mm."""
    return lambda r: "-" if r.get(key) is None else "(" + ", ".join(f"{1e3 * c:.3f}" for c in r[key]) + ")"


def _ratio(a: Any, b: Any) -> float | None:
    return float(a) / float(b) if a is not None and b else None


TABLES["robot"] = Table(
    "Hammerbot (sorofem)",
    "`hammerbot_fine.tet` (shared/data/solidfem) read with scale 0.01, fixed on its 92 nodes at x = -5 cm "
    "(checked against hammerbot.xml), rho = 1070 kg/m^3, gravity (0, -9.8, 0) in the file's own axes, one "
    "load step, tolerance 1e-8. `sorofem/hammerbot` is the issue-2 case (standard, E = 100 kPa, nu = 0.4); "
    "the nu = 0.4999 pair (E = 90 kPa) is the same solve with the mixed (u-p) formulation and with the "
    "standard one, both allowed 200 Newton iterations. Time = wall time of `Body(...)`, `fix` and "
    "`solve_static` (model build included), median of the repeats. Unknowns = free displacement DOFs "
    "(+ one pressure per node for mixed). Tip = the nodes of the x = +5 cm face.",
    (
        _col("case", "case", str),
        _col("formulation", "formulation", str),
        _col("E [kPa]", "youngs_modulus", lambda x: "-" if x is None else f"{x / 1e3:g}"),
        _col("nu", "poisson_ratio", lambda x: "-" if x is None else f"{x:g}"),
        _col("tets", "tets"),
        _col("unknowns", "unknowns"),
        Column("conv.", _status),
        _col("Newton it.", "iterations"),
        _col("time [s]", "seconds"),
        _col("first run [s]", "seconds_first"),
        _col("repeats", "repeats"),
        Column("factor. [ms]", _phase("factorization")),
        Column("report total [ms]", _phase("total")),
        Column("tip u (mean) [mm]", _mm3("tip_displacement")),
        _col("max abs(u) [mm]", "max_displacement_mm", lambda x: _g(x, 4)),
        Column("peak RSS [MiB]", _mib),
    ),
)

TABLES["mixed"] = Table(
    "Mixed formulation cantilevers (sorofem)",
    "The 0.4 m cantilever of the static table (0.1 x 0.1 m, `sf.Mesh.box`, clamped at x = 0, gravity "
    "(0, 0, -9.81), E = 66 kPa, rho = 1080 kg/m^3) with `formulation=\"mixed\"` at nu = 0.4999 (consistent "
    "pressure mass, c(J) = ln J), one load step, tolerance 1e-8. Compare the Newton iterations with the "
    "standard rows at nu = 0.45 above. Unknowns = free displacement DOFs + one pressure per node; the "
    "other columns as in the static table.",
    (
        _col("case", "case", str),
        _col("nu", "poisson_ratio", lambda x: "-" if x is None else f"{x:g}"),
        _col("tets", "tets"),
        _col("unknowns", "unknowns"),
        Column("conv.", _status),
        _col("Newton it.", "iterations"),
        _col("time [s]", "seconds"),
        _col("first run [s]", "seconds_first"),
        _col("repeats", "repeats"),
        Column("assembly [ms]", _phase("assembly")),
        Column("factor. [ms]", _phase("factorization")),
        Column("report total [ms]", _phase("total")),
        Column("fact. (failed)", lambda r: f"{_g(r.get('factorizations'))} ({_g(r.get('failed_factorizations'))})"),
        Column("bare fact. [ms]", lambda r: _ms(r.get("bare_factorization_seconds"))),
        Column("t/it / bare fact.", lambda r: _g(_per_iteration_ratio(r))),
        Column("total / all fact.", lambda r: _g(_factorization_share(r))),
        _col("w_tip [m]", "tip_deflection", lambda x: _g(x, 6)),
        Column("peak RSS [MiB]", _mib),
    ),
)

TABLES["cables"] = Table(
    "Cables (sorofem)",
    "The standard hammerbot solve (E = 100 kPa, nu = 0.4, gravity (0, -9.8, 0)) with two straight cables "
    "of 20 segments each (k = 50 kN/m per segment) along the two long sides of the central bar, "
    "x = -4.5 ... +4.5 cm at y = +0.6 cm (alpha = 0.82, pulled) and y = -0.6 cm (alpha = 1.2, slack), "
    "z = 0. (The body is H-shaped in plan: the bar between the end blocks is only |y| <= 0.75 cm wide, "
    "so the suggested y = +-2.0 cm left 13 of the 21 points (all with |x| < 3 cm) outside the mesh; at "
    "+-0.6 cm, 1.5 mm inside "
    "the bar's faces, all 21 points of each cable are embedded, checked with `cable_placements()`.) "
    "The same solve without the cables runs in the same process, alternating with the cabled one, so "
    "both see the same machine load; times = `Body`, `add_cable`, `fix` and `solve_static`, medians. "
    "The cables change the deformation (the pulled one lifts the tip against gravity), so the Newton "
    "iteration counts differ: t/it = the solver's own Newton time (report total, model build "
    "excluded) / Newton iterations, of the median runs.",
    (
        _col("case", "case", str),
        _col("cable points", "cable_points", lambda x: "-" if x is None else " + ".join(map(str, x))),
        _col("embedded", "embedded", lambda x: "-" if x is None else " + ".join(map(str, x))),
        Column("conv.", _status),
        Column("Newton it. with / without", lambda r: f"{_g(r.get('iterations'))} / {_g(r.get('iterations_without'))}"),
        Column("time with / without [s]", lambda r: f"{_g(r.get('seconds'))} / {_g(r.get('seconds_without'))}"),
        Column("time ratio", lambda r: _g(_ratio(r.get("seconds"), r.get("seconds_without")))),
        Column("t/it with / without [ms]", lambda r: f"{_ms(r.get('seconds_per_iteration'))} / "
               f"{_ms(r.get('seconds_per_iteration_without'))}"),
        Column("t/it ratio", lambda r: _g(_ratio(r.get("seconds_per_iteration"),
                                                  r.get("seconds_per_iteration_without")))),
        _col("repeats", "repeats"),
        Column("tip u with cables [mm]", _mm3("tip_displacement")),
        Column("tip u without [mm]", _mm3("tip_displacement_without")),
        _col("max tension per cable [N]", "max_tension", lambda x: "-" if x is None else " / ".join(_g(t) for t in x)),
        Column("peak RSS [MiB]", _mib),
    ),
)

TABLES["dynamics"] = Table(
    "Dynamics (sorofem)",
    "The standard hammerbot (E = 100 kPa, nu = 0.4, rho = 1070 kg/m^3, clamped at x = -5 cm) released "
    "from rest in its rest shape under gravity (0, -9.8, 0): implicit Euler with lumped mass, "
    "Rayleigh damping alpha_M = 1.0 1/s, beta_K = 0, 1 s at dt = 10 ms (100 steps), Newton tolerance "
    "1e-8 per step, `sf.simulate`. Time = wall time of `Body`, `fix` and `simulate` (one run). "
    "Cutbacks = time steps halved after a Newton failure; a step that still fails after six halvings "
    "raises (conv. = no). The static equilibrium's tip displacement is given for comparison (the "
    "motion is underdamped, so the tip at t = 1 s need not have settled there).",
    (
        _col("case", "case", str),
        _col("dt [ms]", "dt", lambda x: "-" if x is None else f"{1e3 * x:g}"),
        _col("steps", "steps"),
        Column("conv.", _status),
        _col("cutbacks", "cutbacks"),
        _col("Newton it. (total)", "iterations"),
        _col("it./step mean", "mean_iterations_per_step"),
        _col("it./step max", "max_iterations_per_step"),
        _col("time [s]", "seconds"),
        _col("per step [ms]", "seconds_per_step", _ms),
        _col("max KE [J]", "max_kinetic_energy"),
        _col("final KE [J]", "final_kinetic_energy"),
        Column("tip u at t = 1 s [mm]", _mm3("tip_displacement")),
        Column("static tip u [mm]", _mm3("static_tip_displacement")),
        Column("peak RSS [MiB]", _mib),
    ),
)

TABLES["adjoint"] = Table(
    "Adjoint gradient (sorofem)",
    "The standard hammerbot solve (E = 100 kPa, nu = 0.4). Objective O = mean y-position of the tip "
    "nodes (x = +5 cm); `adjoint(dO/dx)` on the model at the converged solution returns dO/d(mu, lambda, "
    "rho per tet, gravity, cable parameters). Forward solve = `Body`, `fix`, `solve_static` (model "
    "build included, as in the hammerbot table); Newton only = the solver's own `report.timings` total. "
    "The first `adjoint` call on a solution factorises the Hessian there; the repeat reuses it. Each "
    "repeat builds a new body, solves and calls `adjoint` twice; medians. Check: dO/dg_y from the "
    "adjoint against the forward sensitivity `forward({\"gravity\": (0, 1, 0)})` (relative difference).",
    (
        _col("case", "case", str),
        _col("tets", "tets"),
        Column("conv.", _status),
        _col("Newton it.", "iterations"),
        _col("forward solve [s]", "seconds_forward"),
        _col("Newton only [s]", "seconds_newton"),
        _col("adjoint, 1st call [s]", "seconds"),
        _col("adjoint, repeat [s]", "seconds_adjoint_repeat"),
        Column("1st adjoint / forward", lambda r: _g(_ratio(r.get("seconds"), r.get("seconds_forward")))),
        Column("1st adjoint / Newton only", lambda r: _g(_ratio(r.get("seconds"), r.get("seconds_newton")))),
        _col("forward sens. [s]", "seconds_forward_sensitivity"),
        _col("repeats", "repeats"),
        _col("dO/dg_y [s^2]", "dO_dgy", lambda x: _g(x, 6)),
        _col("rel. diff adjoint vs forward sens.", "adjoint_vs_forward", lambda x: _g(x, 2)),
        Column("peak RSS [MiB]", _mib),
    ),
)

TABLES["peer"] = Table(
    "scikit-fem peer (benchmarks/peers/skfem_neohookean.py)",
    "The same discrete problem in scikit-fem (P1 tets, same energy, same mesh arrays, same stopping rule) "
    "with plain Newton as in scikit-fem's hyperelasticity example and SciPy's sparse direct solver. "
    "It tries 1, 2, 4, ... load steps until Newton converges; time = the converging run "
    "(mesh and basis construction included), the failed tries listed separately.",
    (
        _col("case", "case", str),
        _col("tets", "tets"),
        _col("free DOFs", "dofs"),
        Column("conv.", _status),
        _col("load steps", "load_steps"),
        _col("Newton it.", "iterations"),
        _col("time [s]", "seconds"),
        _col("incl. failed tries [s]", "seconds_all_attempts"),
        Column("assembly [ms]", _phase("assembly")),
        Column("solve [ms]", _phase("solve")),
        _col("w_tip [m]", "tip_deflection", lambda x: _g(x, 6)),
        Column("peak RSS [MiB]", _mib),
    ),
)


def _cantilever_name(solver: str, length: float, cells: tuple[int, int, int]) -> str:
    return f"{solver}/cantilever-{length:g}m-{'x'.join(map(str, cells))}"


def _tip_deflection(points: np.ndarray, displacement: np.ndarray, length: float) -> float:
    tip = np.abs(points[:, 0] - length) < 1e-9 * max(1.0, length)
    return float(displacement[tip, 2].mean())


def sorofem_cantilever(
    length: float, cells: tuple[int, int, int], formulation: str = "standard", poisson_ratio: float | None = None
) -> dict[str, Any]:
    import sorofem as sf

    mesh = sf.Mesh.box(size=(length, 0.1, 0.1), cells=cells)
    params = dict(MATERIAL) if poisson_ratio is None else {**MATERIAL, "poisson_ratio": poisson_ratio}
    material = sf.NeoHookean(**params)

    def run() -> Any:
        body = sf.Body(mesh, material, formulation=formulation)
        body.fix(mesh.nodes_in_box(min=(-1e-9, -1, -1), max=(1e-9, 1, 1)))
        try:
            return body, sf.solve_static(body, gravity=GRAVITY, tolerance=TOLERANCE, load_steps=1)
        except sf.ConvergenceError as err:
            return body, err

    def bare_factorization(run_result: Any) -> tuple[float, float] | None:
        """This solve's bare factorisation (s) and its time per iteration over it."""
        body, result = run_result
        if isinstance(result, Exception):
            return None
        bare = statistics.median(body._core_model().time_factorization(3))
        report = result.report
        return bare, report.timings["total"] / report.iterations / bare

    timed = repeat_timed(run, budget_s=2.0 if mesh.n_tets < 50_000 else 0.0, after=bare_factorization)
    body, result = timed["result"]
    row = _sorofem_row(mesh, body, result, timed)
    paired = [p for p in timed["after"] if p is not None]
    if paired:
        row["bare_factorization_seconds"] = statistics.median(p[0] for p in paired)
        row["per_iteration_ratios"] = [p[1] for p in paired]
    row["poisson_ratio"] = params["poisson_ratio"]
    if not isinstance(result, Exception):
        row["tip_deflection"] = _tip_deflection(mesh.points, result.displacement, length)
        save_array("displacement", result.displacement)
    return row


def _sorofem_row(mesh: Any, body: Any, result: Any, timed: dict[str, Any]) -> dict[str, Any]:
    report = result.report
    row = {
        "tets": mesh.n_tets,
        "nodes": mesh.n_nodes,
        "dofs": 3 * (mesh.n_nodes - body.fixed_nodes.size),
        # Mixed: plus one pressure per node, fixed nodes included.
        "unknowns": 3 * (mesh.n_nodes - body.fixed_nodes.size) + (mesh.n_nodes if body.formulation == "mixed" else 0),
        "formulation": body.formulation,
        "converged": bool(report.converged) and not isinstance(result, Exception),
        "iterations": report.iterations,
        "load_steps": report.load_steps,
        "cutbacks": report.cutbacks,
        "projected_steps": report.projected_steps,
        "factorizations": report.factorizations,
        "failed_factorizations": report.failed_factorizations,
        "residual_history": report.residual_history,
        "timings": dict(report.timings),
        "seconds": timed["median"],
        "seconds_first": timed["first"],
        "repeats": len(timed["times"]),
        "all_seconds": timed["times"],
    }
    if isinstance(result, Exception):
        row["failure"] = str(result)
    return row


STATIC_CANTILEVERS = [
    # (length m, cells, quick): 6 nx ny nz tets ~ 200, 1.5k, 12k, 100k for 0.4 m
    (0.4, (8, 2, 2), True),
    (0.4, (16, 4, 4), True),
    (0.4, (32, 8, 8), False),
    (0.4, (64, 16, 16), False),
    (1.0, (8, 2, 2), True),
    (1.0, (16, 4, 4), True),
    (1.0, (48, 8, 8), False),
]
for _length, _cells, _quick in STATIC_CANTILEVERS:
    case(_cantilever_name("sorofem", _length, _cells), "static", _quick)(
        partial(sorofem_cantilever, _length, _cells)
    )


MIXED_NU = 0.4999
MIXED_CANTILEVERS = [
    # (length m, cells, quick); standard counterparts at nu = 0.45 are in STATIC_CANTILEVERS
    (0.4, (8, 2, 2), True),
    (0.4, (16, 4, 4), True),
    (0.4, (64, 16, 16), False),
]
for _length, _cells, _quick in MIXED_CANTILEVERS:
    case(_cantilever_name("sorofem", _length, _cells) + f"-mixed-nu{MIXED_NU:g}", "mixed", _quick)(
        partial(sorofem_cantilever, _length, _cells, "mixed", MIXED_NU)
    )


# ---------------------------------------------------------------------------
# Hammerbot: static (standard and mixed), cables, dynamics, adjoint

HAMMERBOT_FIXED_COUNT = 92
HAMMERBOT_GRAVITY = (0.0, -9.8, 0.0)
HAMMERBOT_MATERIAL = dict(youngs_modulus=100e3, poisson_ratio=0.4, density=1070.0)
# Two straight cables along the long sides of the central bar (|y| <= 7.5 mm, |z| <= 10 mm between
# the end blocks at |x| >= 3 cm): (start, actuation alpha); direction +x, 9 cm, 20 segments.
HAMMERBOT_CABLES = [((-0.045, 0.006, 0.0), 0.82), ((-0.045, -0.006, 0.0), 1.2)]
HAMMERBOT_CABLE_LENGTH = 0.09
HAMMERBOT_CABLE_DIVISIONS = 20
HAMMERBOT_CABLE_STIFFNESS = 50e3  # N/m per segment


def _public_api(sf: Any, *names: str) -> bool:
    """Whether the Python API has ``names`` (``"Cable"``, ``"Body.add_cable"``, ...).

    Set SOROFEM_BENCH_CORE_ONLY=1 to time the ``sorofem._core.Model`` fallback instead.
    """
    if os.environ.get("SOROFEM_BENCH_CORE_ONLY"):
        return False
    for name in names:
        obj = sf
        for part in name.split("."):
            if not hasattr(obj, part):
                return False
            obj = getattr(obj, part)
    return True


def _hammerbot_mesh() -> tuple[Any, np.ndarray]:
    """The hammerbot mesh (m) and its 92 clamped nodes, checked against hammerbot.xml."""
    import sorofem as sf

    mesh = sf.Mesh.read(SOLIDFEM_DATA / "hammerbot_fine.tet", scale=0.01)
    fixed = mesh.nodes_in_box(min=(-0.05 - 1e-6, -1, -1), max=(-0.05 + 1e-6, 1, 1))
    assert fixed.size == HAMMERBOT_FIXED_COUNT, f"expected {HAMMERBOT_FIXED_COUNT} nodes at x = -5 cm, found {fixed.size}"
    dirichlet = ET.parse(SOLIDFEM_DATA / "hammerbot.xml").getroot().find("model/dirichlet")
    listed = np.array(sorted(int(i) for i in dirichlet.text.split()))
    assert np.array_equal(fixed, listed), "the x = -5 cm nodes differ from hammerbot.xml's <dirichlet> list"
    return mesh, fixed


def _tip_mean(mesh: Any, displacement: np.ndarray) -> list[float]:
    tip = np.abs(mesh.points[:, 0] - mesh.points[:, 0].max()) < 1e-9
    return np.asarray(displacement)[tip].mean(axis=0).tolist()


def hammerbot_static(
    formulation: str = "standard", youngs_modulus: float = 100e3, poisson_ratio: float = 0.4,
    max_iterations: int = 50,
) -> dict[str, Any]:
    import sorofem as sf

    mesh, fixed = _hammerbot_mesh()
    material = sf.NeoHookean(youngs_modulus=youngs_modulus, poisson_ratio=poisson_ratio, density=1070.0)

    def run() -> Any:
        body = sf.Body(mesh, material, formulation=formulation)
        body.fix(fixed)
        try:
            return body, sf.solve_static(
                body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE, load_steps=1, max_iterations=max_iterations
            )
        except sf.ConvergenceError as err:
            return body, err

    timed = repeat_timed(run, budget_s=3.0)
    body, result = timed["result"]
    row = _sorofem_row(mesh, body, result, timed)
    row.update(youngs_modulus=youngs_modulus, poisson_ratio=poisson_ratio, max_iterations=max_iterations)
    if not isinstance(result, Exception):
        tip = np.abs(mesh.points[:, 0] - mesh.points[:, 0].max()) < 1e-9
        row["tip_nodes"] = int(tip.sum())
        row["tip_displacement"] = _tip_mean(mesh, result.displacement)
        row["max_displacement_mm"] = 1e3 * result.max_displacement
    return row


case("sorofem/hammerbot", "robot", quick=True)(hammerbot_static)
case(f"sorofem/hammerbot-mixed-nu{MIXED_NU:g}", "robot", quick=True)(
    partial(hammerbot_static, "mixed", 90e3, MIXED_NU, 200)
)
case(f"sorofem/hammerbot-standard-nu{MIXED_NU:g}", "robot", quick=True)(
    partial(hammerbot_static, "standard", 90e3, MIXED_NU, 200)
)


def _cabled_hammerbot_solve(mesh: Any, fixed: np.ndarray, with_cables: bool) -> dict[str, Any]:
    """One static hammerbot solve with or without the two cables, through ``sf.Cable`` /
    ``body.add_cable`` when the Python API has them, else through ``sorofem._core.Model``.
    Returns a plain dict (converged, iterations, timings, displacement, tensions, placements)."""
    import sorofem as sf

    material = sf.NeoHookean(**HAMMERBOT_MATERIAL)
    lines = [(start, alpha) for start, alpha in HAMMERBOT_CABLES] if with_cables else []
    try:
        if _public_api(sf, "Cable.line", "Body.add_cable"):
            body = sf.Body(mesh, material)
            body.fix(fixed)
            for start, alpha in lines:
                body.add_cable(sf.Cable.line(start, (1.0, 0.0, 0.0), HAMMERBOT_CABLE_LENGTH, HAMMERBOT_CABLE_DIVISIONS,
                                             stiffness=HAMMERBOT_CABLE_STIFFNESS, actuation=alpha))
            result = sf.solve_static(body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE, load_steps=1)
            report = result.report
            return {
                "api": "sorofem.Cable / Body.add_cable / solve_static",
                "converged": bool(report.converged), "iterations": report.iterations,
                "timings": dict(report.timings), "displacement": result.displacement,
                "tensions": [np.asarray(t) for t in (result.cable_tensions or [])],
                "placements": lambda: [[p.kind for p in c] for c in body.cable_placements()],
            }
        from sorofem import _core

        specs = []
        for start, alpha in lines:
            t = np.linspace(0.0, HAMMERBOT_CABLE_LENGTH, HAMMERBOT_CABLE_DIVISIONS + 1)
            points = np.asarray(start) + t[:, None] * np.array([1.0, 0.0, 0.0])
            specs.append({"points": points, "stiffness": HAMMERBOT_CABLE_STIFFNESS, "actuation": alpha})
        model = _core.Model(mesh.points, mesh.tets, fixed, "standard", None, cables=specs or None)
        model.set_material(*material.per_element(mesh.n_tets))
        out = model.solve(np.array(HAMMERBOT_GRAVITY), np.zeros((mesh.n_nodes, 3)), np.zeros((fixed.size, 3)),
                          None, TOLERANCE, 50, 1)
        return {
            "api": "sorofem._core.Model(cables=...)",
            "converged": bool(out["converged"]), "iterations": out["iterations"],
            "timings": dict(out["timings"]), "displacement": out["positions"] - mesh.points,
            "tensions": [np.asarray(t) for t in out.get("cable_tensions", [])],
            "placements": lambda: [[p[0] for p in c] for c in model.cable_placements()],
        }
    except sf.ConvergenceError as err:
        report = err.report if isinstance(err.report, dict) else getattr(err.report, "__dict__", {})
        return {"converged": False, "iterations": report.get("iterations"),
                "timings": dict(report.get("timings") or {}), "failure": str(err)}


def _newton_seconds_per_iteration(res: dict[str, Any]) -> float | None:
    total = (res.get("timings") or {}).get("total")
    return total / res["iterations"] if total and res.get("iterations") else None


@case("sorofem/hammerbot-2-cables", "cables", quick=True)
def sorofem_hammerbot_cables() -> dict[str, Any]:
    mesh, fixed = _hammerbot_mesh()
    times: dict[bool, list[float]] = {True: [], False: []}
    results: dict[bool, list[dict[str, Any]]] = {True: [], False: []}
    placements: list[list[str]] | None = None
    start = time.perf_counter()
    # Alternate with and without cables so that both see the same load on a shared machine.
    while len(times[True]) < 7 and (not times[True] or time.perf_counter() - start < 8.0):
        for with_cables in (True, False):
            t0 = time.perf_counter()
            res = _cabled_hammerbot_solve(mesh, fixed, with_cables)
            times[with_cables].append(time.perf_counter() - t0)
            where = res.pop("placements", None)  # holds the body: query it once, then let it go
            if with_cables and placements is None and where is not None:
                placements = where()
            results[with_cables].append(res)

    def median(with_cables: bool) -> tuple[float, dict[str, Any]]:
        ts = times[with_cables]
        i = sorted(range(len(ts)), key=ts.__getitem__)[(len(ts) - 1) // 2]
        return ts[i], results[with_cables][i]

    (sec, res), (sec0, res0) = median(True), median(False)
    row: dict[str, Any] = {
        "api": res.get("api"),
        "tets": mesh.n_tets,
        "converged": res["converged"] and res0["converged"],
        "iterations": res["iterations"], "iterations_without": res0["iterations"],
        "seconds": sec, "seconds_without": sec0,
        "seconds_first": times[True][0], "seconds_first_without": times[False][0],
        "all_seconds": times[True], "all_seconds_without": times[False],
        "repeats": len(times[True]),
        "timings": res["timings"], "timings_without": res0["timings"],
        # Newton time (the solver's own total, model build excluded) per iteration.
        "seconds_per_iteration": _newton_seconds_per_iteration(res),
        "seconds_per_iteration_without": _newton_seconds_per_iteration(res0),
    }
    if res.get("failure") or res0.get("failure"):
        row["failure"] = res.get("failure") or res0.get("failure")
    if "displacement" in res and placements is not None:
        row["cable_points"] = [len(c) for c in placements]
        row["embedded"] = [sum(kind == "embedded" for kind in c) for c in placements]
        row["placements"] = placements
        row["tip_displacement"] = _tip_mean(mesh, res["displacement"])
        row["max_tension"] = [float(t.max(initial=0.0)) for t in res["tensions"]]
        row["tensions"] = [t.tolist() for t in res["tensions"]]
        row["note"] = (f"via {res['api']}; cables: " + "; ".join(
            f"y = {1e2 * s[1]:+g} cm, alpha = {a:g}" for s, a in HAMMERBOT_CABLES)
            + f"; segment tensions of the pulled cable {_g(min(res['tensions'][0]))} ... "
            f"{_g(max(res['tensions'][0]))} N, slack cable max {_g(max(res['tensions'][1]))} N")
    if "displacement" in res0:
        row["tip_displacement_without"] = _tip_mean(mesh, res0["displacement"])
    return row


DYNAMICS_DT = 0.01
DYNAMICS_STEPS = 100
DYNAMICS_MASS_DAMPING = 1.0


@case("sorofem/hammerbot-dynamics-1s", "dynamics", quick=True)
def sorofem_hammerbot_dynamics() -> dict[str, Any]:
    import sorofem as sf

    mesh, fixed = _hammerbot_mesh()
    material = sf.NeoHookean(**HAMMERBOT_MATERIAL)
    row: dict[str, Any] = {"tets": mesh.n_tets, "dt": DYNAMICS_DT, "steps": DYNAMICS_STEPS,
                           "mass_damping": DYNAMICS_MASS_DAMPING}
    t0 = time.perf_counter()
    try:
        if _public_api(sf, "simulate"):
            row["api"] = "sorofem.simulate"
            body = sf.Body(mesh, material)
            body.fix(fixed)
            traj = sf.simulate(body, DYNAMICS_DT, DYNAMICS_STEPS, gravity=HAMMERBOT_GRAVITY,
                               damping=(DYNAMICS_MASS_DAMPING, 0.0), tolerance=TOLERANCE)
            iterations, cutbacks = np.asarray(traj.iterations), traj.cutbacks
            kinetic, final = np.asarray(traj.kinetic_energy), traj.final_positions
        else:
            from sorofem import _core

            row["api"] = "sorofem._core.Model.simulate"
            model = _core.Model(mesh.points, mesh.tets, fixed, "standard")
            model.set_material(*material.per_element(mesh.n_tets))
            out = model.simulate(np.array(HAMMERBOT_GRAVITY), np.zeros((mesh.n_nodes, 3)), np.zeros((fixed.size, 3)),
                                 DYNAMICS_DT, DYNAMICS_STEPS, np.zeros((DYNAMICS_STEPS, 0)),
                                 mass_damping=DYNAMICS_MASS_DAMPING, tolerance=TOLERANCE)
            iterations, cutbacks = np.asarray(out["iterations"]), out["cutbacks"]
            kinetic, final = np.asarray(out["kinetic_energy"]), np.asarray(out["positions"])[-1]
    except sf.ConvergenceError as err:
        row.update(converged=False, failure=str(err), seconds=time.perf_counter() - t0)
        return row
    seconds = time.perf_counter() - t0
    row.update(
        converged=True, seconds=seconds, seconds_per_step=seconds / DYNAMICS_STEPS,
        iterations=int(iterations.sum()), iterations_per_step=iterations.tolist(),
        mean_iterations_per_step=float(iterations.mean()), max_iterations_per_step=int(iterations.max()),
        cutbacks=int(cutbacks), max_kinetic_energy=float(kinetic.max()), final_kinetic_energy=float(kinetic[-1]),
        tip_displacement=_tip_mean(mesh, final - mesh.points), note=f"via {row['api']}",
    )
    body = sf.Body(mesh, material)
    body.fix(fixed)
    static = sf.solve_static(body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE)
    row["static_tip_displacement"] = _tip_mean(mesh, static.displacement)
    return row


@case("sorofem/hammerbot-adjoint", "adjoint", quick=True)
def sorofem_hammerbot_adjoint() -> dict[str, Any]:
    import sorofem as sf

    mesh, fixed = _hammerbot_mesh()
    material = sf.NeoHookean(**HAMMERBOT_MATERIAL)
    tip = np.abs(mesh.points[:, 0] - mesh.points[:, 0].max()) < 1e-9
    d_objective = np.zeros((mesh.n_nodes, 3))
    d_objective[tip, 1] = 1.0 / tip.sum()  # O = mean y-position of the tip nodes
    rounds: list[dict[str, Any]] = []
    start = time.perf_counter()
    while len(rounds) < 7 and (not rounds or time.perf_counter() - start < 6.0):
        t0 = time.perf_counter()
        body = sf.Body(mesh, material)
        body.fix(fixed)
        result = sf.solve_static(body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE)
        t1 = time.perf_counter()
        model = body._core_model()  # the model holding this equilibrium (no public adjoint yet)
        gradient = model.adjoint(d_objective)
        t2 = time.perf_counter()
        model.adjoint(d_objective)
        t3 = time.perf_counter()
        dx = model.forward({"gravity": np.array([0.0, 1.0, 0.0])})["dx"]
        t4 = time.perf_counter()
        rounds.append({
            "forward": t1 - t0, "newton": result.report.timings["total"], "iterations": result.report.iterations,
            "converged": bool(result.report.converged), "adjoint": t2 - t1, "adjoint_repeat": t3 - t2,
            "forward_sensitivity": t4 - t3, "dO_dgy": float(np.asarray(gradient["gravity"])[1]),
            "dO_dgy_forward": float(np.sum(d_objective * np.asarray(dx))),
        })

    def med(key: str) -> float:
        return float(statistics.median(r[key] for r in rounds))

    last = rounds[-1]
    return {
        "tets": mesh.n_tets, "converged": all(r["converged"] for r in rounds), "iterations": last["iterations"],
        "seconds": med("adjoint"), "seconds_adjoint_repeat": med("adjoint_repeat"),
        "seconds_forward": med("forward"), "seconds_newton": med("newton"),
        "seconds_forward_sensitivity": med("forward_sensitivity"), "repeats": len(rounds), "rounds": rounds,
        "dO_dgy": last["dO_dgy"],
        "adjoint_vs_forward": abs(last["dO_dgy"] - last["dO_dgy_forward"]) / abs(last["dO_dgy_forward"]),
    }


def skfem_cantilever(length: float, cells: tuple[int, int, int]) -> dict[str, Any]:
    from peers.skfem_neohookean import solve_with_load_steps

    from peers.skfem_neohookean import box_mesh

    points, tets, source = box_points_tets((length, 0.1, 0.1), cells)
    helper_points, helper_tets = box_mesh((length, 0.1, 0.1), cells)
    helper_matches = bool(np.array_equal(helper_tets, tets) and np.allclose(helper_points, points, rtol=0, atol=1e-15))
    fixed = np.flatnonzero(np.abs(points[:, 0]) <= 1e-9)
    result = solve_with_load_steps(
        points, tets, fixed, MATERIAL["youngs_modulus"], MATERIAL["poisson_ratio"], MATERIAL["density"],
        GRAVITY, tol=TOLERANCE,
    )
    save_array("displacement", result["displacement"])
    tries = ", ".join(f"{steps} ({'converged' if ok else 'failed'} after {it} it., {_g(sec)} s)"
                      for steps, ok, it, sec in result["attempts"])
    note = f"load steps tried: {tries}; mesh from {source}"
    if not helper_matches:
        note += "; **the peer's box_mesh helper differs from sorofem.Mesh.box**"
    return {
        "note": note,
        "tets": len(tets),
        "nodes": len(points),
        "dofs": 3 * (len(points) - fixed.size),
        "mesh_source": source,
        "helper_mesh_matches_core": helper_matches,
        "converged": result["converged"],
        "iterations": result["newton_iterations"],
        "load_steps": result["load_steps"],
        "attempts": result["attempts"],
        "seconds": result["seconds"],
        "seconds_all_attempts": result["seconds_all_attempts"],
        "timings": result["timings"],
        "residual_history": result["residual_history"],
        "failure": result["failure"],
        "tip_deflection": _tip_deflection(points, result["displacement"], length),
    }


# (length m, cells, quick, last). The 1 m 48x8x8 peer needs 128 load steps of plain Newton
# (~15 minutes): it runs after every other case and never with --quick.
PEER_CANTILEVERS = [(0.4, (8, 2, 2), True, False), (1.0, (16, 4, 4), True, False), (1.0, (48, 8, 8), False, True)]
for _length, _cells, _quick, _last in PEER_CANTILEVERS:
    case(_cantilever_name("skfem", _length, _cells), "peer", _quick, _last)(partial(skfem_cantilever, _length, _cells))


# ---------------------------------------------------------------------------
# Sections computed from all rows


def comparison(rows: dict[str, dict[str, Any]], array_dir: Path) -> str:
    """sorofem vs scikit-fem on the same meshes: speed ratio and agreement of the solutions."""
    out = [
        "| mesh | tets | sorofem it. | sorofem [s] | skfem it. (load steps) | skfem [s] | skfem / sorofem "
        "| incl. failed tries | w_tip sorofem [m] | w_tip skfem [m] | rel. diff w_tip | max abs(du) / max abs(u) |",
        "|" + "---|" * 12,
    ]
    for name, peer in rows.items():
        if not name.startswith("skfem/"):
            continue
        ours = rows.get("sorofem/" + name.split("/", 1)[1])
        if ours is None or peer.get("error") or ours.get("error"):
            continue
        speedup = peer["seconds"] / ours["seconds"] if ours.get("seconds") else None
        speedup_all = peer["seconds_all_attempts"] / ours["seconds"] if ours.get("seconds") else None
        w_a, w_b = ours.get("tip_deflection"), peer.get("tip_deflection")
        rel_w = abs(w_a - w_b) / abs(w_a) if w_a and w_b is not None else None
        u_a = load_array("sorofem/" + name.split("/", 1)[1], "displacement", array_dir)
        u_b = load_array(name, "displacement", array_dir)
        rel_u = None
        if u_a is not None and u_b is not None and u_a.shape == u_b.shape:
            rel_u = float(np.abs(u_a - u_b).max() / np.abs(u_a).max())
        peer["speedup"], ours["speedup_vs_skfem"] = speedup, speedup
        peer["rel_diff_tip"], peer["rel_diff_u"] = rel_w, rel_u
        out.append(
            f"| {name.split('/', 1)[1]} | {ours['tets']} | {ours['iterations']} | {_g(ours['seconds'])} "
            f"| {peer['iterations']} ({peer['load_steps']}) | {_g(peer['seconds'])} | **{_g(speedup)}x** "
            f"| {_g(speedup_all)}x | {_g(w_a, 8)} | {_g(w_b, 8)} | {_g(rel_w, 2)} | {_g(rel_u, 2)} |"
        )
    if len(out) == 2:
        return "No pair of sorofem and scikit-fem cases ran.\n"
    return "\n".join(out) + "\n"


PAPER_HAMMERBOT_SECONDS = 7.6  # the paper's hammerbot static solve


def targets(rows: dict[str, dict[str, Any]]) -> str:
    """Every issue's targets against the measured numbers."""
    lines = ["| target | case | measured | limit | met |", "|---|---|---|---|---|"]

    def add(target: str, case_name: str, value: float | None, limit: float, unit: str = "",
            at_least: bool = False) -> None:
        bound = (">= " if at_least else "<= ") + f"{limit:g}{unit}"
        if value is None:
            lines.append(f"| {target} | {case_name} | not measured | {bound} | - |")
        else:
            ok = "yes" if (value >= limit if at_least else value <= limit) else "**NO**"
            lines.append(f"| {target} | {case_name} | {_g(value)}{unit} | {bound} | {ok} |")

    def ok_row(name: str) -> dict[str, Any] | None:
        r = rows.get(name)
        return r if r and not r.get("error") and r.get("converged") else None

    def static_case(name: str) -> bool:
        return name in CASES and CASES[name].table == "static"

    # Issue 2: static Neo-Hookean solves.
    r = ok_row("sorofem/hammerbot")
    add("hammerbot static solve time", "sorofem/hammerbot", r and r["seconds"], 0.25, " s")
    for name, limit in [("sorofem/cantilever-0.4m-8x2x2", 12), ("sorofem/cantilever-1m-8x2x2", 25),
                        ("sorofem/cantilever-1m-16x4x4", 25), ("sorofem/cantilever-1m-48x8x8", 25)]:
        if name in rows:
            r = rows[name]
            add("Newton iterations, one load step", name, None if r.get("error") else r.get("iterations"), limit)
    for name, r in rows.items():
        if static_case(name) and r.get("tets", 0) >= 10_000 and not r.get("error"):
            add("time per Newton iteration / one bare numeric factorisation", name, _per_iteration_ratio(r), 1.3)
    for name, r in rows.items():
        if static_case(name) and r.get("tets", 0) >= 90_000:
            add("peak memory, ~100k tets", name, r.get("peak_rss_mib") and r["peak_rss_mib"] / 1024, 8.0, " GiB")
    for name, r in rows.items():
        if name.startswith("skfem/") and r.get("speedup"):
            add("speed-up over scikit-fem (time skfem / sorofem)", name, r["speedup"], 50, "x", at_least=True)

    # Mixed formulation.
    mixed_bot, std_bot = f"sorofem/hammerbot-mixed-nu{MIXED_NU:g}", "sorofem/hammerbot"
    if mixed_bot in rows:
        m, s = ok_row(mixed_bot), ok_row(std_bot)
        add(f"hammerbot mixed (nu = {MIXED_NU:g}) solve time / standard hammerbot solve time (nu = 0.4)",
            f"{mixed_bot} vs {std_bot}", m and s and _ratio(m["seconds"], s["seconds"]), 2.0, "x")
        add(f"hammerbot mixed solve time, >= 10x faster than the paper's {PAPER_HAMMERBOT_SECONDS:g} s",
            mixed_bot, m and m["seconds"], PAPER_HAMMERBOT_SECONDS / 10, " s")
    mixed_small = _cantilever_name("sorofem", 0.4, (8, 2, 2)) + f"-mixed-nu{MIXED_NU:g}"
    std_small = _cantilever_name("sorofem", 0.4, (8, 2, 2))
    if mixed_small in rows:
        m, s = ok_row(mixed_small), ok_row(std_small)
        limit = s["iterations"] if s else None
        if limit is None:
            lines.append(f"| Newton iterations, mixed at nu = {MIXED_NU:g} vs standard at nu = 0.45 | {mixed_small} "
                         f"| {_g(m and m['iterations'])} | standard not measured | - |")
        else:
            add(f"Newton iterations, mixed at nu = {MIXED_NU:g} <= standard at nu = 0.45 ({std_small})",
                mixed_small, m and m["iterations"], limit)
    for name, r in rows.items():
        if name in CASES and CASES[name].table == "mixed" and r.get("tets", 0) >= 90_000:
            add("peak memory, ~100k tets, mixed", name,
                r.get("peak_rss_mib") and r["peak_rss_mib"] / 1024, 12.0, " GiB")

    # Cables.
    r = rows.get("sorofem/hammerbot-2-cables")
    if r is not None:
        good = ok_row("sorofem/hammerbot-2-cables")
        add("static solve time with two cables / without (same process, alternating)", "sorofem/hammerbot-2-cables",
            good and _ratio(good["seconds"], good["seconds_without"]), 1.15, "x")
        add("time per Newton iteration with two cables / without", "sorofem/hammerbot-2-cables",
            good and _ratio(good["seconds_per_iteration"], good["seconds_per_iteration_without"]), 1.15, "x")
        add("hammerbot with two cables, static solve time", "sorofem/hammerbot-2-cables",
            good and good["seconds"], 0.4, " s")

    # Dynamics.
    r = rows.get("sorofem/hammerbot-dynamics-1s")
    if r is not None:
        good = ok_row("sorofem/hammerbot-dynamics-1s")
        add("1 s of hammerbot dynamics at dt = 10 ms, time", "sorofem/hammerbot-dynamics-1s",
            good and good["seconds"], 10.0, " s")
        failed = bool(r.get("error") or not r.get("converged"))
        lines.append(f"| 1 s of hammerbot dynamics: no Newton failure | sorofem/hammerbot-dynamics-1s | "
                     f"{'failed' if failed else 'none'} ({_g(r.get('cutbacks'))} cutbacks, "
                     f"{_g(r.get('iterations'))} Newton it.) | no failure | {'**NO**' if failed else 'yes'} |")

    # Adjoint.
    r = rows.get("sorofem/hammerbot-adjoint")
    if r is not None:
        good = ok_row("sorofem/hammerbot-adjoint")
        add("adjoint (1st call, incl. its factorisation) / forward solve", "sorofem/hammerbot-adjoint",
            good and _ratio(good["seconds"], good["seconds_forward"]), 0.25, "x")
    return "\n".join(lines) + "\n"


def run_log(rows: dict[str, dict[str, Any]]) -> str:
    """Order, wall time and machine load of each case (other jobs may share the machine)."""
    out = ["| # | case | child wall time [s] | load average at case start (1, 5, 15 min) |", "|---|---|---|---|"]
    for i, (name, r) in enumerate(rows.items(), 1):
        load = r.get("load_at_start")
        out.append(f"| {i} | {name} | {_g(r.get('child_wall_s'))} | "
                   f"{'-' if load is None else ', '.join(f'{x:.2f}' for x in load)} |")
    return "\n".join(out) + "\n"


# ---------------------------------------------------------------------------
# Machine and provenance


def _run_text(cmd: list[str]) -> str:
    try:
        return subprocess.run(cmd, capture_output=True, text=True, cwd=REPO, timeout=30).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return ""


def machine() -> dict[str, str]:
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    ram = "unknown"
    try:
        kib = int(re.search(r"MemTotal:\s+(\d+)", Path("/proc/meminfo").read_text()).group(1))
        ram = f"{kib / 1024**2:.1f} GiB"
    except (OSError, AttributeError):
        pass
    os_name = platform.platform()
    try:
        pretty = re.search(r'PRETTY_NAME="([^"]+)"', Path("/etc/os-release").read_text())
        if pretty:
            os_name = f"{pretty.group(1)} (kernel {platform.release()})"
    except OSError:
        pass
    versions = []
    for module in ("numpy", "scipy", "skfem", "sorofem"):
        try:
            versions.append(f"{module} {__import__(module).__version__}")
        except Exception:  # noqa: BLE001 - any import failure just means "not available"
            versions.append(f"{module} not importable")
    commit = _run_text(["git", "rev-parse", "--short=12", "HEAD"]) or "no commit yet"
    if _run_text(["git", "status", "--porcelain", "--untracked-files=no"]) or commit == "no commit yet":
        commit += " (with uncommitted changes)"
    return {
        "CPU": cpu,
        "cores": f"{os.cpu_count()} logical (affinity: {len(os.sched_getaffinity(0))})",
        "RAM": ram,
        "OS": os_name,
        "Python": f"{platform.python_version()} ({sys.executable})",
        "rustc": _run_text(["rustc", "--version"]) or "not found",
        "packages": ", ".join(versions),
        "date (start)": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "git commit": commit,
        "sorofem extension": extension_stamp(),
        "load average at start (1, 5, 15 min)": ", ".join(f"{x:.2f}" for x in os.getloadavg()),
    }


def extension_stamp() -> str:
    """Path and modification time of the compiled extension, to notice a rebuild during the run."""
    try:
        import sorofem._core as core

        path = Path(core.__file__)
        when = dt.datetime.fromtimestamp(path.stat().st_mtime, dt.timezone.utc)
        return f"{path.name}, built {when:%Y-%m-%d %H:%M:%S} UTC"
    except (ImportError, OSError, AttributeError):
        return "not built"


def _command() -> str:
    exe = Path(sys.executable)
    try:
        exe = exe.relative_to(Path.cwd())
    except ValueError:
        pass
    script = Path(sys.argv[0])
    try:
        script = script.resolve().relative_to(Path.cwd())
    except ValueError:
        pass
    return shlex.join([str(exe), str(script), *sys.argv[1:]])


# ---------------------------------------------------------------------------
# Parent: run cases in children, write the report


@dataclass
class Run:
    rows: dict[str, dict[str, Any]] = field(default_factory=dict)
    array_dir: Path = Path(".")


def run_child(name: str, workdir: Path) -> dict[str, Any]:
    """Run one case in a fresh interpreter; its peak RSS comes from ``wait4``'s rusage."""
    out_json = workdir / f"{_safe(name)}.json"
    log = workdir / f"{_safe(name)}.log"
    cmd = [sys.executable, str(Path(__file__).resolve()), "--child", name, "--workdir", str(workdir)]
    load_at_start = list(os.getloadavg())
    start = time.perf_counter()
    with open(log, "wb") as log_file:
        proc = subprocess.Popen(cmd, stdout=log_file, stderr=subprocess.STDOUT, cwd=REPO)
        while True:
            pid, status, usage = os.wait4(proc.pid, os.WNOHANG)
            if pid:
                break
            if time.perf_counter() - start > CASE_TIMEOUT_S:
                proc.kill()
                pid, status, usage = os.wait4(proc.pid, 0)
                break
            time.sleep(0.02)
    proc.returncode = os.waitstatus_to_exitcode(status)
    wall = time.perf_counter() - start
    row: dict[str, Any] = {}
    if out_json.exists():
        row = json.loads(out_json.read_text())
    if proc.returncode != 0 or not row:
        lines = log.read_text(errors="replace").strip().splitlines() or ["(no output)"]
        row.setdefault("error", f"child exited with {proc.returncode}: {lines[-1]} (log: {log.name})")
        row["log_tail"] = lines[-30:]
    row["case"] = name
    row["peak_rss_mib"] = usage.ru_maxrss / 1024  # KiB on Linux
    row["child_wall_s"] = wall
    row["load_at_start"] = load_at_start
    return row


def child_main(name: str, workdir: Path) -> int:
    global _ARRAY_DIR, _CURRENT_CASE
    _ARRAY_DIR, _CURRENT_CASE = workdir, name
    row = CASES[name].run()
    if "sorofem" in sys.modules:
        row["extension"] = extension_stamp()
    (workdir / f"{_safe(name)}.json").write_text(json.dumps(row, default=_json_default))
    return 0


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")


def render(run: Run, info: dict[str, str], command: str, quick: bool) -> str:
    parts = [
        "# Benchmarks",
        "",
        "Written by `benchmarks/run.py`; do not edit by hand. Every case ran in a fresh Python process; "
        "peak RSS is that process's `ru_maxrss` (interpreter, numpy and the extension included).",
        "",
        f"Command: `{command}`" + (" (quick: small cases only)" if quick else ""),
        "",
        "| machine | |",
        "|---|---|",
        *(f"| {k} | {v} |" for k, v in info.items()),
        "",
    ]
    for key, table in TABLES.items():
        rows = [r for r in run.rows.values() if CASES[r["case"]].table == key]
        if not rows:
            continue
        parts += [f"## {table.title}", "", table.description, ""]
        parts.append("| " + " | ".join(c.header for c in table.columns) + " |")
        parts.append("|" + "---|" * len(table.columns))
        for r in rows:
            parts.append("| " + " | ".join(c.format(r) for c in table.columns) + " |")
        notes = [f"- {r['case']}: {r.get('error') or r.get('failure') or r.get('note')}"
                 for r in rows if r.get("error") or r.get("failure") or r.get("note")]
        parts += ["", *notes, ""] if notes else [""]
    parts += [f"## {COMPARISON_TITLE}", "", comparison(run.rows, run.array_dir)]
    parts += [f"## {TARGETS_TITLE}", "", targets(run.rows)]
    parts += [f"## {RUN_LOG_TITLE}", "", "Cases in the order they ran, each in its own process.", "",
              run_log(run.rows)]
    return "\n".join(parts)


COMPARISON_TITLE = "sorofem vs scikit-fem on identical meshes"
TARGETS_TITLE = "Targets"
RUN_LOG_TITLE = "Run log"
# Titles this runner wrote in earlier versions: replaced, not kept, when the file is rewritten.
FORMER_TITLES = {"Targets (issue 2)"}


def owned_titles() -> set[str]:
    """The ``## `` sections written by this runner (whether or not this run renders them)."""
    return {t.title for t in TABLES.values()} | {COMPARISON_TITLE, TARGETS_TITLE, RUN_LOG_TITLE} | FORMER_TITLES


def foreign_sections(text: str) -> list[str]:
    """The ``## `` sections of an existing report that this runner does not own (e.g. "Locking
    study", written by examples/02_locking_study.py), verbatim, in their order."""
    chunks = re.split(r"(?m)^(?=## )", text)
    kept = []
    for chunk in chunks[1:]:  # chunks[0] is the preamble, which the runner owns
        title = chunk.splitlines()[0][3:].strip()
        if title not in owned_titles():
            kept.append(chunk.rstrip("\n") + "\n")
    return kept


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--write", metavar="PATH", help="write the Markdown report here")
    parser.add_argument("--quick", action="store_true", help="small cases only")
    parser.add_argument("--only", metavar="GLOB", action="append", help="run the cases matching (repeatable)")
    parser.add_argument("--list", action="store_true", help="list the cases and exit")
    parser.add_argument("--json", metavar="PATH", help="also dump the raw rows as JSON")
    parser.add_argument("--child", metavar="CASE", help=argparse.SUPPRESS)
    parser.add_argument("--workdir", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)

    if args.child:
        return child_main(args.child, args.workdir)

    selected = [c for c in CASES.values() if (c.quick or not args.quick)]
    if args.only:
        selected = [c for c in selected if any(fnmatch.fnmatch(c.name, p) for p in args.only)]
    selected.sort(key=lambda c: c.last)  # stable: registration order, the slow ``last`` cases at the end
    if args.list:
        for c in selected:
            print(f"{c.name:48s} table={c.table:8s} {'quick' if c.quick else '':5s} {'last' if c.last else ''}")
        return 0
    if not selected:
        print("no case selected", file=sys.stderr)
        return 2

    command = _command()
    info = machine()
    with tempfile.TemporaryDirectory(prefix="sorofem-bench-") as tmp:
        run = Run(array_dir=Path(tmp))
        for c in selected:
            print(f"[bench] {c.name} ...", end=" ", flush=True)
            row = run_child(c.name, Path(tmp))
            run.rows[c.name] = row
            if row.get("error"):
                print("ERROR:", row["error"][-400:], flush=True)
            else:
                print(
                    f"{'converged' if row.get('converged') else 'NOT converged'}, "
                    f"{row.get('iterations')} it., {_g(row.get('seconds'))} s, "
                    f"peak RSS {row['peak_rss_mib']:.0f} MiB (child {row['child_wall_s']:.1f} s)",
                    flush=True,
                )
        report = render(run, info, command, args.quick)
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    report = report.replace("\n\n## ", f"\n| load average at end (1, 5, 15 min) | {load} |\n\n## ", 1)
    # Only the rows that time sorofem itself must share one build (the peers use it for meshes only).
    builds = sorted({r["extension"] for n, r in run.rows.items() if n.startswith("sorofem/") and "extension" in r})
    if len(builds) > 1:
        warning = (f"**Warning: the extension was rebuilt during this run ({' -> '.join(builds)}); "
                   "the sorofem rows come from different builds. Run again.**")
        print("[bench]", warning, file=sys.stderr)
        report = report.replace("\n| machine | |", f"\n{warning}\n\n| machine | |", 1)
    if args.write:
        path = Path(args.write)
        if path.exists():
            kept = foreign_sections(path.read_text(encoding="utf-8"))
            if kept:
                report = report.rstrip("\n") + "\n\n" + "\n".join(kept)
                print(f"[bench] kept sections of {path} not written by this runner: "
                      + ", ".join(repr(k.splitlines()[0][3:].strip()) for k in kept))
        tmp_path = path.with_suffix(path.suffix + ".tmp")
        tmp_path.write_text(report)
        tmp_path.replace(path)
        print(f"[bench] wrote {path}")
    else:
        print(report)
    if args.json:
        Path(args.json).write_text(json.dumps(run.rows, indent=1, default=_json_default))
    return 1 if any(r.get("error") for r in run.rows.values()) else 0


if __name__ == "__main__":
    sys.exit(main())
