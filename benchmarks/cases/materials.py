"""The hammerbot's static solve with a Yeoh silicone against the same solve with Neo-Hookean,
timed side by side in one process (issue 15: at most 1.3x, Newton iterations within 2)."""

from __future__ import annotations

from functools import partial
from typing import Any

from harness import TABLES, Column, Row, Table, case, col, fmt, mib, mm3, ms, ratio, status

from .common import HAMMERBOT_GRAVITY, MIXED_NU, TOLERANCE, alternate, hammerbot_mesh, tip_mean
from .hammerbot import hammerbot_material

TABLES["materials"] = Table(
    "Yeoh against Neo-Hookean (sorofem)",
    "The hammerbot static solve of the hammerbot table (one load step, tolerance 1e-8) with the Yeoh "
    "silicone of its `-yeoh` rows (2 c10 = mu, 2/d1 = K, c20 = -mu/50, c30 = mu/500) and with Neo-Hookean of "
    "the same E and nu: standard at E = 100 kPa, nu = 0.4, and mixed at E = 90 kPa, nu = 0.4999 (200 Newton "
    "iterations allowed). The two solves alternate in the same process, so both see the same machine load; "
    "times = `Body`, `fix` and `solve_static`, medians. t/it = the solver's own Newton time (report total, "
    "model build excluded) / Newton iterations, of the median runs.",
    (
        col("case", "case", str),
        col("formulation", "formulation", str),
        Column("conv.", status),
        Column("Newton it. Yeoh / NH", lambda r: f"{fmt(r.get('iterations'))} / {fmt(r.get('iterations_neo_hookean'))}"),
        Column("time Yeoh / NH [s]", lambda r: f"{fmt(r.get('seconds'))} / {fmt(r.get('seconds_neo_hookean'))}"),
        Column("time ratio", lambda r: fmt(ratio(r.get("seconds"), r.get("seconds_neo_hookean")))),
        Column("t/it Yeoh / NH [ms]", lambda r: f"{ms(r.get('seconds_per_iteration'))} / "
               f"{ms(r.get('seconds_per_iteration_neo_hookean'))}"),
        Column("t/it ratio", lambda r: fmt(ratio(r.get("seconds_per_iteration"),
                                                  r.get("seconds_per_iteration_neo_hookean")))),
        col("repeats", "repeats"),
        Column("tip u Yeoh [mm]", mm3("tip_displacement")),
        Column("tip u NH [mm]", mm3("tip_displacement_neo_hookean")),
        Column("peak RSS [MiB]", mib),
    ),
)


def _solve(mesh: Any, fixed: Any, model: str, formulation: str, youngs_modulus: float, poisson_ratio: float,
           max_iterations: int) -> Row:
    import sorofem as sf

    material = hammerbot_material(model, youngs_modulus, poisson_ratio)
    try:
        body = sf.Body(mesh, material, formulation=formulation)
        body.fix(fixed)
        result = sf.solve_static(body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE, load_steps=1,
                                 max_iterations=max_iterations)
    except sf.ConvergenceError as err:
        return {"converged": False, "iterations": None, "timings": {}, "failure": str(err)}
    report = result.report
    return {"converged": bool(report.converged), "iterations": report.iterations, "timings": dict(report.timings),
            "tip_displacement": tip_mean(mesh, result.displacement)}


def yeoh_against_neo_hookean(formulation: str, youngs_modulus: float, poisson_ratio: float,
                             max_iterations: int) -> Row:
    mesh, fixed = hammerbot_mesh()
    runs = alternate({model: partial(_solve, mesh, fixed, model, formulation, youngs_modulus, poisson_ratio,
                                     max_iterations)
                      for model in ("yeoh", "neo-hookean")})
    yeoh, neo = runs["yeoh"], runs["neo-hookean"]

    def per_iteration(res: Row) -> float | None:
        total = res["timings"].get("total")
        return total / res["iterations"] if total and res.get("iterations") else None

    row: Row = {
        "tets": mesh.n_tets, "formulation": formulation,
        "youngs_modulus": youngs_modulus, "poisson_ratio": poisson_ratio,
        "converged": yeoh["result"]["converged"] and neo["result"]["converged"],
        "iterations": yeoh["result"]["iterations"], "iterations_neo_hookean": neo["result"]["iterations"],
        "seconds": yeoh["seconds"], "seconds_neo_hookean": neo["seconds"],
        "all_seconds": yeoh["all_seconds"], "all_seconds_neo_hookean": neo["all_seconds"],
        "repeats": yeoh["repeats"],
        "timings": yeoh["result"]["timings"], "timings_neo_hookean": neo["result"]["timings"],
        "seconds_per_iteration": per_iteration(yeoh["result"]),
        "seconds_per_iteration_neo_hookean": per_iteration(neo["result"]),
        "tip_displacement": yeoh["result"].get("tip_displacement"),
        "tip_displacement_neo_hookean": neo["result"].get("tip_displacement"),
    }
    failure = yeoh["result"].get("failure") or neo["result"].get("failure")
    if failure:
        row["failure"] = failure
    return row


case("sorofem/hammerbot-yeoh-vs-neo-hookean", "materials", quick=True)(
    partial(yeoh_against_neo_hookean, "standard", 100e3, 0.4, 50)
)
case(f"sorofem/hammerbot-yeoh-vs-neo-hookean-mixed-nu{MIXED_NU:g}", "materials", quick=True)(
    partial(yeoh_against_neo_hookean, "mixed", 90e3, MIXED_NU, 200)
)
