"""The adjoint gradient at the standard hammerbot's equilibrium, against its forward solve."""

from __future__ import annotations

import statistics
import time

import numpy as np

from harness import TABLES, Column, Row, Table, case, col, fmt, mib, ratio, status

from .common import HAMMERBOT_GRAVITY, HAMMERBOT_MATERIAL, TOLERANCE, hammerbot_mesh

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
        col("case", "case", str),
        col("tets", "tets"),
        Column("conv.", status),
        col("Newton it.", "iterations"),
        col("forward solve [s]", "seconds_forward"),
        col("Newton only [s]", "seconds_newton"),
        col("adjoint, 1st call [s]", "seconds"),
        col("adjoint, repeat [s]", "seconds_adjoint_repeat"),
        Column("1st adjoint / forward", lambda r: fmt(ratio(r.get("seconds"), r.get("seconds_forward")))),
        Column("1st adjoint / Newton only", lambda r: fmt(ratio(r.get("seconds"), r.get("seconds_newton")))),
        col("forward sens. [s]", "seconds_forward_sensitivity"),
        col("repeats", "repeats"),
        col("dO/dg_y [s^2]", "dO_dgy", lambda x: fmt(x, 6)),
        col("rel. diff adjoint vs forward sens.", "adjoint_vs_forward", lambda x: fmt(x, 2)),
        Column("peak RSS [MiB]", mib),
    ),
)


@case("sorofem/hammerbot-adjoint", "adjoint", quick=True)
def sorofem_hammerbot_adjoint() -> Row:
    import sorofem as sf

    mesh, fixed = hammerbot_mesh()
    material = sf.NeoHookean(**HAMMERBOT_MATERIAL)
    tip = np.abs(mesh.points[:, 0] - mesh.points[:, 0].max()) < 1e-9
    d_objective = np.zeros((mesh.n_nodes, 3))
    d_objective[tip, 1] = 1.0 / tip.sum()  # O = mean y-position of the tip nodes
    rounds: list[Row] = []
    start = time.perf_counter()
    while len(rounds) < 7 and (not rounds or time.perf_counter() - start < 6.0):
        t0 = time.perf_counter()
        body = sf.Body(mesh, material)
        body.fix(fixed)
        result = sf.solve_static(body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE)
        t1 = time.perf_counter()
        # The core model at this equilibrium: sf.gradient solves and differentiates in one call, and
        # this case times the adjoint apart from the solve.
        model = body._core_model()
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

