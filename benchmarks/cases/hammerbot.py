"""The hammerbot of the paper (shared/data/solidfem) at its static equilibrium under gravity:
standard formulation, and nearly incompressible in the mixed and the standard formulation."""

from __future__ import annotations

from functools import partial
from typing import Any

import numpy as np

from harness import TABLES, Column, Row, Table, case, col, fmt, mib, mm3, phase, repeat_timed, status

from .common import HAMMERBOT_GRAVITY, MIXED_NU, TOLERANCE, hammerbot_mesh, sorofem_row, tip_mean

TABLES["robot"] = Table(
    "Hammerbot (sorofem)",
    "`hammerbot_fine.tet` (shared/data/solidfem) read with scale 0.01, fixed on its 92 nodes at x = -5 cm "
    "(checked against hammerbot.xml), rho = 1070 kg/m^3, gravity (0, -9.8, 0) in the file's own axes, one "
    "load step, tolerance 1e-8. `sorofem/hammerbot` is the issue-2 case (standard, E = 100 kPa, nu = 0.4); "
    "the nu = 0.4999 pair (E = 90 kPa) is the same solve with the mixed (u-p) formulation and with the "
    "standard one, both allowed 200 Newton iterations. The `-yeoh` rows: a Yeoh silicone with the same small-strain moduli (2 c10 = mu, 2/d1 = K, c20 = -mu/50, c30 = mu/500; E and nu shown are those). Time = wall time of `Body(...)`, `fix` and "
    "`solve_static` (model build included), median of the repeats. Unknowns = free displacement DOFs "
    "(+ one pressure per node for mixed). Tip = the nodes of the x = +5 cm face.",
    (
        col("case", "case", str),
        col("formulation", "formulation", str),
        col("E [kPa]", "youngs_modulus", lambda x: "-" if x is None else f"{x / 1e3:g}"),
        col("nu", "poisson_ratio", lambda x: "-" if x is None else f"{x:g}"),
        col("tets", "tets"),
        col("unknowns", "unknowns"),
        Column("conv.", status),
        col("Newton it.", "iterations"),
        col("time [s]", "seconds"),
        col("first run [s]", "seconds_first"),
        col("repeats", "repeats"),
        Column("factor. [ms]", phase("factorization")),
        Column("report total [ms]", phase("total")),
        Column("tip u (mean) [mm]", mm3("tip_displacement")),
        col("max abs(u) [mm]", "max_displacement_mm", lambda x: fmt(x, 4)),
        Column("peak RSS [MiB]", mib),
    ),
)


def hammerbot_material(model: str, youngs_modulus: float, poisson_ratio: float) -> Any:
    """Neo-Hookean, or a Yeoh silicone with the same small-strain moduli (2 c10 = mu, 2/d1 = K)
    softening then stiffening at large strain (c20 = -mu/50, c30 = mu/500)."""
    import sorofem as sf

    if model == "neo-hookean":
        return sf.NeoHookean(youngs_modulus=youngs_modulus, poisson_ratio=poisson_ratio, density=1070.0)
    mu = youngs_modulus / (2 * (1 + poisson_ratio))
    bulk = youngs_modulus / (3 * (1 - 2 * poisson_ratio))
    return sf.Yeoh(c10=mu / 2, c20=-mu / 50, c30=mu / 500, d1=2 / bulk, density=1070.0)


def hammerbot_static(
    formulation: str = "standard", youngs_modulus: float = 100e3, poisson_ratio: float = 0.4,
    max_iterations: int = 50, model: str = "neo-hookean",
) -> Row:
    import sorofem as sf

    mesh, fixed = hammerbot_mesh()
    material = hammerbot_material(model, youngs_modulus, poisson_ratio)

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
    row = sorofem_row(mesh, body, result, timed)
    row.update(youngs_modulus=youngs_modulus, poisson_ratio=poisson_ratio, max_iterations=max_iterations)
    if not isinstance(result, Exception):
        tip = np.abs(mesh.points[:, 0] - mesh.points[:, 0].max()) < 1e-9
        row["tip_nodes"] = int(tip.sum())
        row["tip_displacement"] = tip_mean(mesh, result.displacement)
        row["max_displacement_mm"] = 1e3 * result.max_displacement
    return row


case("sorofem/hammerbot", "robot", quick=True)(hammerbot_static)
case(f"sorofem/hammerbot-mixed-nu{MIXED_NU:g}", "robot", quick=True)(
    partial(hammerbot_static, "mixed", 90e3, MIXED_NU, 200)
)
case(f"sorofem/hammerbot-standard-nu{MIXED_NU:g}", "robot", quick=True)(
    partial(hammerbot_static, "standard", 90e3, MIXED_NU, 200)
)
case("sorofem/hammerbot-yeoh", "robot", quick=True)(partial(hammerbot_static, model="yeoh"))
case(f"sorofem/hammerbot-yeoh-mixed-nu{MIXED_NU:g}", "robot", quick=True)(
    partial(hammerbot_static, "mixed", 90e3, MIXED_NU, 200, "yeoh")
)
