"""Static solves of the paper's cantilever at growing mesh sizes (standard formulation)."""

from __future__ import annotations

from functools import partial

from harness import TABLES, Column, Table, case, col, fmt, mib, ms, phase, status

from .common import cantilever_name, factorization_share, per_iteration_ratio, sorofem_cantilever

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
        col("case", "case", str),
        col("tets", "tets"),
        col("free DOFs", "dofs"),
        Column("conv.", status),
        col("Newton it.", "iterations"),
        col("time [s]", "seconds"),
        col("first run [s]", "seconds_first"),
        col("repeats", "repeats"),
        Column("assembly [ms]", phase("assembly")),
        Column("factor. [ms]", phase("factorization")),
        Column("solve [ms]", phase("solve")),
        Column("line search [ms]", phase("line_search")),
        Column("report total [ms]", phase("total")),
        Column("fact. (failed)", lambda r: f"{fmt(r.get('factorizations'))} ({fmt(r.get('failed_factorizations'))})"),
        Column("bare fact. [ms]", lambda r: ms(r.get("bare_factorization_seconds"))),
        Column("t/it / bare fact.", lambda r: fmt(per_iteration_ratio(r))),
        Column("total / all fact.", lambda r: fmt(factorization_share(r))),
        col("w_tip [m]", "tip_deflection", lambda x: fmt(x, 6)),
        Column("peak RSS [MiB]", mib),
    ),
)

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
    case(cantilever_name("sorofem", _length, _cells), "static", _quick)(partial(sorofem_cantilever, _length, _cells))
