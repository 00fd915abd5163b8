"""The cantilever in the mixed (u-p) formulation, nearly incompressible."""

from __future__ import annotations

from functools import partial

from harness import TABLES, Column, Table, case, col, fmt, mib, ms, phase, status

from .common import MIXED_NU, cantilever_name, factorization_share, per_iteration_ratio, sorofem_cantilever

TABLES["mixed"] = Table(
    "Mixed formulation cantilevers (sorofem)",
    "The 0.4 m cantilever of the static table (0.1 x 0.1 m, `sf.Mesh.box`, clamped at x = 0, gravity "
    "(0, 0, -9.81), E = 66 kPa, rho = 1080 kg/m^3) with `formulation=\"mixed\"` at nu = 0.4999 (consistent "
    "pressure mass, c(J) = ln J), one load step, tolerance 1e-8. Compare the Newton iterations with the "
    "standard rows at nu = 0.45 above. Unknowns = free displacement DOFs + one pressure per node; the "
    "other columns as in the static table.",
    (
        col("case", "case", str),
        col("nu", "poisson_ratio", lambda x: "-" if x is None else f"{x:g}"),
        col("tets", "tets"),
        col("unknowns", "unknowns"),
        Column("conv.", status),
        col("Newton it.", "iterations"),
        col("time [s]", "seconds"),
        col("first run [s]", "seconds_first"),
        col("repeats", "repeats"),
        Column("assembly [ms]", phase("assembly")),
        Column("factor. [ms]", phase("factorization")),
        Column("report total [ms]", phase("total")),
        Column("fact. (failed)", lambda r: f"{fmt(r.get('factorizations'))} ({fmt(r.get('failed_factorizations'))})"),
        Column("bare fact. [ms]", lambda r: ms(r.get("bare_factorization_seconds"))),
        Column("t/it / bare fact.", lambda r: fmt(per_iteration_ratio(r))),
        Column("total / all fact.", lambda r: fmt(factorization_share(r))),
        col("w_tip [m]", "tip_deflection", lambda x: fmt(x, 6)),
        Column("peak RSS [MiB]", mib),
    ),
)

MIXED_CANTILEVERS = [
    # (length m, cells, quick); standard counterparts at nu = 0.45 are in static.STATIC_CANTILEVERS
    (0.4, (8, 2, 2), True),
    (0.4, (16, 4, 4), True),
    (0.4, (64, 16, 16), False),
]
for _length, _cells, _quick in MIXED_CANTILEVERS:
    case(cantilever_name("sorofem", _length, _cells) + f"-mixed-nu{MIXED_NU:g}", "mixed", _quick)(
        partial(sorofem_cantilever, _length, _cells, "mixed", MIXED_NU)
    )
