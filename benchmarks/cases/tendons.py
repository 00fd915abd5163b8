"""The hammerbot bent by a sliding tendon against the same pull by the paper's spring chain,
timed side by side in one process (issue 16: at most 1.3x, Newton iterations included)."""

from __future__ import annotations

from functools import partial
from typing import Any

from harness import TABLES, Column, Row, Table, case, col, fmt, mib, mm3, ms, ratio, status

from .common import HAMMERBOT_GRAVITY, HAMMERBOT_MATERIAL, TOLERANCE, alternate, hammerbot_mesh, tip_mean

# examples/16_hammerbot_tendons.py: two routes at y = +-6 mm, z = 0, x = -4.5 ... +4.5 cm, 18
# segments, the first point anchored (the motor); (y, alpha) with the pull (1 - alpha) L0.
TENDON_ROUTES = ((0.006, 0.82), (-0.006, 1.2))
TENDON_START_X = -0.045
TENDON_LENGTH = 0.09
TENDON_DIVISIONS = 18
PAPER_STIFFNESS = 50e3  # N/m per segment

TABLES["tendons"] = Table(
    "Tendons against spring chains (sorofem)",
    "The standard hammerbot solve (E = 100 kPa, nu = 0.4, gravity (0, -9.8, 0), one load step from rest, "
    "tolerance 1e-8) with the two routes of examples/16_hammerbot_tendons.py (y = +-0.6 cm, z = 0, x = -4.5 "
    "... +4.5 cm, 18 segments, first point anchored in the world: the motor), as sliding tendons pulled "
    "d = (1 - alpha) L0 = 16.2 mm and -18 mm (slack), and as the paper's spring chains at alpha = 0.82 / 1.2 "
    "with k = 50 kN/m per segment. The two solves alternate in the same process, so both see the same "
    "machine load; times = `Body`, `add_cable`, `fix` and `solve_static`, medians. t/it = the solver's own "
    "Newton time (report total, model build excluded) / Newton iterations, of the median runs.",
    (
        col("case", "case", str),
        Column("conv.", status),
        Column("Newton it. tendon / springs", lambda r: f"{fmt(r.get('iterations'))} / {fmt(r.get('iterations_springs'))}"),
        Column("time tendon / springs [s]", lambda r: f"{fmt(r.get('seconds'))} / {fmt(r.get('seconds_springs'))}"),
        Column("time ratio", lambda r: fmt(ratio(r.get("seconds"), r.get("seconds_springs")))),
        Column("t/it tendon / springs [ms]", lambda r: f"{ms(r.get('seconds_per_iteration'))} / "
               f"{ms(r.get('seconds_per_iteration_springs'))}"),
        Column("t/it ratio", lambda r: fmt(ratio(r.get("seconds_per_iteration"),
                                                  r.get("seconds_per_iteration_springs")))),
        col("repeats", "repeats"),
        col("tendon T [N]", "tension"),
        Column("spring tensions [N]", lambda r: "-" if not r.get("spring_tension_range") else
               " ... ".join(fmt(t) for t in r["spring_tension_range"])),
        Column("tip u tendon [mm]", mm3("tip_displacement")),
        Column("tip u springs [mm]", mm3("tip_displacement_springs")),
        Column("peak RSS [MiB]", mib),
    ),
)


def _solve(mesh: Any, fixed: Any, model: str) -> Row:
    import sorofem as sf

    try:
        body = sf.Body(mesh, sf.NeoHookean(**HAMMERBOT_MATERIAL))
        body.fix(fixed)
        for y, alpha in TENDON_ROUTES:
            command = ({"model": "tendon", "pull": (1.0 - alpha) * TENDON_LENGTH} if model == "tendon"
                       else {"stiffness": PAPER_STIFFNESS, "actuation": alpha})
            body.add_cable(sf.Cable.line((TENDON_START_X, y, 0.0), (1.0, 0.0, 0.0), TENDON_LENGTH, TENDON_DIVISIONS,
                                         anchor_first=True, **command))
        result = sf.solve_static(body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE, load_steps=1)
    except sf.ConvergenceError as err:
        return {"converged": False, "iterations": None, "timings": {}, "failure": str(err)}
    report = result.report
    return {"converged": bool(report.converged), "iterations": report.iterations, "timings": dict(report.timings),
            "tip_displacement": tip_mean(mesh, result.displacement),
            "tension": result.cable_tension[0],
            "tension_range": [float(result.cable_tensions[0].min()), float(result.cable_tensions[0].max())]}


@case("sorofem/hammerbot-tendons-vs-springs", "tendons", quick=True)
def tendons_against_springs() -> Row:
    mesh, fixed = hammerbot_mesh()
    runs = alternate({model: partial(_solve, mesh, fixed, model) for model in ("tendon", "springs")})
    tendon, springs = runs["tendon"]["result"], runs["springs"]["result"]

    def per_iteration(res: Row) -> float | None:
        total = res["timings"].get("total")
        return total / res["iterations"] if total and res.get("iterations") else None

    row: Row = {
        "tets": mesh.n_tets,
        "converged": tendon["converged"] and springs["converged"],
        "iterations": tendon["iterations"], "iterations_springs": springs["iterations"],
        "seconds": runs["tendon"]["seconds"], "seconds_springs": runs["springs"]["seconds"],
        "all_seconds": runs["tendon"]["all_seconds"], "all_seconds_springs": runs["springs"]["all_seconds"],
        "repeats": runs["tendon"]["repeats"],
        "timings": tendon["timings"], "timings_springs": springs["timings"],
        "seconds_per_iteration": per_iteration(tendon), "seconds_per_iteration_springs": per_iteration(springs),
        "tension": tendon.get("tension"), "spring_tension_range": springs.get("tension_range"),
        "tip_displacement": tendon.get("tip_displacement"),
        "tip_displacement_springs": springs.get("tip_displacement"),
    }
    failure = tendon.get("failure") or springs.get("failure")
    if failure:
        row["failure"] = failure
    return row
