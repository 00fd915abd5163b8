"""The standard hammerbot released from rest under gravity: implicit Euler over 1 s."""

from __future__ import annotations

import time

import numpy as np

from harness import TABLES, Column, Row, Table, case, col, mib, mm3, ms, status

from .common import HAMMERBOT_GRAVITY, HAMMERBOT_MATERIAL, TOLERANCE, hammerbot_mesh, tip_mean

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
        col("case", "case", str),
        col("dt [ms]", "dt", lambda x: "-" if x is None else f"{1e3 * x:g}"),
        col("steps", "steps"),
        Column("conv.", status),
        col("cutbacks", "cutbacks"),
        col("Newton it. (total)", "iterations"),
        col("it./step mean", "mean_iterations_per_step"),
        col("it./step max", "max_iterations_per_step"),
        col("time [s]", "seconds"),
        col("per step [ms]", "seconds_per_step", ms),
        col("max KE [J]", "max_kinetic_energy"),
        col("final KE [J]", "final_kinetic_energy"),
        Column("tip u at t = 1 s [mm]", mm3("tip_displacement")),
        Column("static tip u [mm]", mm3("static_tip_displacement")),
        Column("peak RSS [MiB]", mib),
    ),
)


DYNAMICS_DT = 0.01
DYNAMICS_STEPS = 100
DYNAMICS_MASS_DAMPING = 1.0


@case("sorofem/hammerbot-dynamics-1s", "dynamics", quick=True)
def sorofem_hammerbot_dynamics() -> Row:
    import sorofem as sf

    mesh, fixed = hammerbot_mesh()
    material = sf.NeoHookean(**HAMMERBOT_MATERIAL)
    row: Row = {"tets": mesh.n_tets, "dt": DYNAMICS_DT, "steps": DYNAMICS_STEPS,
                "mass_damping": DYNAMICS_MASS_DAMPING, "api": "sorofem.simulate"}
    t0 = time.perf_counter()
    try:
        body = sf.Body(mesh, material)
        body.fix(fixed)
        traj = sf.simulate(body, DYNAMICS_DT, DYNAMICS_STEPS, gravity=HAMMERBOT_GRAVITY,
                           damping=(DYNAMICS_MASS_DAMPING, 0.0), tolerance=TOLERANCE)
    except sf.ConvergenceError as err:
        row.update(converged=False, failure=str(err), seconds=time.perf_counter() - t0)
        return row
    seconds = time.perf_counter() - t0
    iterations, kinetic = np.asarray(traj.iterations), np.asarray(traj.kinetic_energy)
    row.update(
        converged=True, seconds=seconds, seconds_per_step=seconds / DYNAMICS_STEPS,
        iterations=int(iterations.sum()), iterations_per_step=iterations.tolist(),
        mean_iterations_per_step=float(iterations.mean()), max_iterations_per_step=int(iterations.max()),
        cutbacks=int(traj.cutbacks), max_kinetic_energy=float(kinetic.max()), final_kinetic_energy=float(kinetic[-1]),
        tip_displacement=tip_mean(mesh, traj.final_positions - mesh.points), note=f"via {row['api']}",
    )
    body = sf.Body(mesh, material)
    body.fix(fixed)
    static = sf.solve_static(body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE)
    row["static_tip_displacement"] = tip_mean(mesh, static.displacement)
    return row
