"""What several case families share: the paper's cantilever and hammerbot set-ups, one timed
static solve of a cantilever, a solve's row, and the time-per-iteration ratio."""

from __future__ import annotations

import statistics
import xml.etree.ElementTree as ET
from typing import Any

import numpy as np

from harness import REPO, Row, repeat_timed, save_array

SOLIDFEM_DATA = REPO.parent / "shared" / "data" / "solidfem"

# The cantilever of the paper: 0.1 x 0.1 m, clamped at x = 0, under gravity.
MATERIAL = dict(youngs_modulus=66e3, poisson_ratio=0.45, density=1080.0)
GRAVITY = (0.0, 0.0, -9.81)
TOLERANCE = 1e-8
#: Poisson's ratio of the nearly incompressible (mixed formulation) cases.
MIXED_NU = 0.4999

HAMMERBOT_FIXED_COUNT = 92
HAMMERBOT_GRAVITY = (0.0, -9.8, 0.0)
HAMMERBOT_MATERIAL = dict(youngs_modulus=100e3, poisson_ratio=0.4, density=1070.0)


def cantilever_name(solver: str, length: float, cells: tuple[int, int, int]) -> str:
    return f"{solver}/cantilever-{length:g}m-{'x'.join(map(str, cells))}"


def tip_deflection(points: np.ndarray, displacement: np.ndarray, length: float) -> float:
    """Mean z-displacement of the x = ``length`` face, m."""
    tip = np.abs(points[:, 0] - length) < 1e-9 * max(1.0, length)
    return float(displacement[tip, 2].mean())


def sorofem_cantilever(
    length: float, cells: tuple[int, int, int], formulation: str = "standard", poisson_ratio: float | None = None
) -> Row:
    """The cantilever's static solve in one load step, timed with its model build; each solve is
    paired with a bare factorisation of its Hessian timed right after it."""
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
        # The core model holds the factorisation; the Python API has no timer for it.
        bare = statistics.median(body._core_model().time_factorization(3))
        report = result.report
        return bare, report.timings["total"] / report.iterations / bare

    timed = repeat_timed(run, budget_s=2.0 if mesh.n_tets < 50_000 else 0.0, after=bare_factorization)
    body, result = timed["result"]
    row = sorofem_row(mesh, body, result, timed)
    paired = [p for p in timed["after"] if p is not None]
    if paired:
        row["bare_factorization_seconds"] = statistics.median(p[0] for p in paired)
        row["per_iteration_ratios"] = [p[1] for p in paired]
    row["poisson_ratio"] = params["poisson_ratio"]
    if not isinstance(result, Exception):
        row["tip_deflection"] = tip_deflection(mesh.points, result.displacement, length)
        save_array("displacement", result.displacement)
    return row


def sorofem_row(mesh: Any, body: Any, result: Any, timed: dict[str, Any]) -> Row:
    """The row of a timed static solve (``result``: a StaticResult or the ConvergenceError)."""
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


def per_iteration_ratio(r: Row) -> float | None:
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


def factorization_share(r: Row) -> float | None:
    """Total solve time over the time of all numeric factorisations, failed ones included."""
    t = r.get("timings") or {}
    return t["total"] / t["factorization"] if t.get("factorization") else None


def hammerbot_mesh() -> tuple[Any, np.ndarray]:
    """The hammerbot mesh (m) and its 92 clamped nodes, checked against hammerbot.xml."""
    import sorofem as sf

    mesh = sf.Mesh.read(SOLIDFEM_DATA / "hammerbot_fine.tet", scale=0.01)
    fixed = mesh.nodes_in_box(min=(-0.05 - 1e-6, -1, -1), max=(-0.05 + 1e-6, 1, 1))
    assert fixed.size == HAMMERBOT_FIXED_COUNT, f"expected {HAMMERBOT_FIXED_COUNT} nodes at x = -5 cm, found {fixed.size}"
    dirichlet = ET.parse(SOLIDFEM_DATA / "hammerbot.xml").getroot().find("model/dirichlet")
    listed = np.array(sorted(int(i) for i in dirichlet.text.split()))
    assert np.array_equal(fixed, listed), "the x = -5 cm nodes differ from hammerbot.xml's <dirichlet> list"
    return mesh, fixed


def tip_mean(mesh: Any, displacement: np.ndarray) -> list[float]:
    """Mean displacement of the hammerbot's tip nodes (its x = +5 cm face), m."""
    tip = np.abs(mesh.points[:, 0] - mesh.points[:, 0].max()) < 1e-9
    return np.asarray(displacement)[tip].mean(axis=0).tolist()


def alternate(solves: dict[str, Any], min_repeats: int = 7, budget_s: float = 8.0) -> dict[str, Any]:
    """Time several solves of one comparison in the same process, one after the other in turn
    (so that all see the same load on a shared machine), at least once each and until each ran
    ``min_repeats`` times or ``budget_s`` passed. ``solves``: name -> function returning a plain
    dict (a row's worth). Returns name -> ``{"seconds": median, "all_seconds", "result": the
    dict of the median run, "repeats"}``."""
    import time

    times: dict[str, list[float]] = {name: [] for name in solves}
    results: dict[str, list[Any]] = {name: [] for name in solves}
    start = time.perf_counter()
    while min(map(len, times.values())) < min_repeats and (
            not min(map(len, times.values())) or time.perf_counter() - start < budget_s):
        for name, solve in solves.items():
            t0 = time.perf_counter()
            results[name].append(solve())
            times[name].append(time.perf_counter() - t0)
    out = {}
    for name, ts in times.items():
        i = sorted(range(len(ts)), key=ts.__getitem__)[(len(ts) - 1) // 2]
        out[name] = {"seconds": ts[i], "all_seconds": ts, "result": results[name][i], "repeats": len(ts)}
    return out
