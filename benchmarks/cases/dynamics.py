"""The standard hammerbot released from rest under gravity: implicit Euler over 1 s."""

from __future__ import annotations

from typing import Any

import numpy as np

from harness import TABLES, Column, Row, Table, case, col, mib, mm3, ms, repeat_timed, status

from .common import HAMMERBOT_GRAVITY, HAMMERBOT_MATERIAL, TOLERANCE, hammerbot_mesh, tip_mean

TABLES["dynamics"] = Table(
    "Dynamics (sorofem)",
    "The standard hammerbot (E = 100 kPa, nu = 0.4, rho = 1070 kg/m^3, clamped at x = -5 cm) released "
    "from rest in its rest shape under gravity (0, -9.8, 0): implicit Euler with lumped mass, "
    "Rayleigh damping alpha_M = 1.0 1/s, beta_K = 0, 1 s at dt = 10 ms (100 steps), Newton tolerance "
    "1e-8 per step, `sf.simulate` with each step method (`method=`: `newton` refactorises at every "
    "iteration, `modified` (the default) keeps the factorisation across iterations and steps, rotated with "
    "the body, `linearly_implicit` takes one kept-factor iteration per step); the `-fast` row is `modified` "
    "at tolerance 1e-2, the fast mode of the real-time table. Time = wall time of `Body`, `fix` and "
    "`simulate`, the median of the repeats (up to 5 runs in one process, while the time spent stays under "
    "5 s: the machine is a shared 2-core VM, whose single runs vary); first run = the first of them. "
    "Factorisations = numeric factorisations of the step Hessian; single prec. = those of them in single "
    "precision (the kept ones; docs/theory.md, \"Dynamics\"). Tip deviation = "
    "the largest distance over the 101 frames between the tip's mean displacement and that of a "
    "tight-tolerance run (`newton`, tolerance 1e-11), relative to the largest tip displacement of that "
    "run. Cutbacks = time steps halved after a Newton failure; a step that still fails after six "
    "halvings raises (conv. = no). The static equilibrium's tip displacement is given for comparison "
    "(the motion is underdamped, so the tip at t = 1 s need not have settled there).",
    (
        col("case", "case", str),
        col("method", "method", str),
        col("tolerance", "tolerance", lambda x: "-" if x is None else f"{x:g}"),
        col("dt [ms]", "dt", lambda x: "-" if x is None else f"{1e3 * x:g}"),
        col("steps", "steps"),
        Column("conv.", status),
        col("cutbacks", "cutbacks"),
        col("Newton it. (total)", "iterations"),
        col("it./step mean", "mean_iterations_per_step"),
        col("fact./step mean", "mean_factorizations_per_step"),
        col("single prec.", "single_precision_factorizations"),
        col("time [s]", "seconds"),
        col("first run [s]", "seconds_first"),
        col("repeats", "repeats"),
        col("per step [ms]", "seconds_per_step", ms),
        col("tip deviation [%]", "max_tip_deviation_percent"),
        col("final KE [J]", "final_kinetic_energy"),
        Column("tip u at t = 1 s [mm]", mm3("tip_displacement")),
        Column("static tip u [mm]", mm3("static_tip_displacement")),
        Column("peak RSS [MiB]", mib),
    ),
)


DYNAMICS_DT = 0.01
DYNAMICS_STEPS = 100
DYNAMICS_MASS_DAMPING = 1.0


REFERENCE_TOLERANCE = 1e-11
#: The fast mode's tolerance (the real-time table's).
FAST_TOLERANCE = 1e-2


#: Repeats of a timed run: while the time spent stays under the budget, at most this many.
TIMING_BUDGET_S, MAX_RUNS = 5.0, 5


def _simulate_hammerbot(method: str, tolerance: float, budget_s: float = 0.0) -> tuple[Any, Any, dict[str, Any]]:
    """The hammerbot, its trajectory by ``method`` and the wall times of building and simulating
    (:func:`harness.repeat_timed`: one run unless ``budget_s`` allows more)."""
    import sorofem as sf

    mesh, fixed = hammerbot_mesh()

    def run() -> Any:
        body = sf.Body(mesh, sf.NeoHookean(**HAMMERBOT_MATERIAL))
        body.fix(fixed)
        return sf.simulate(body, DYNAMICS_DT, DYNAMICS_STEPS, gravity=HAMMERBOT_GRAVITY,
                           damping=(DYNAMICS_MASS_DAMPING, 0.0), tolerance=tolerance, method=method)

    timed = repeat_timed(run, budget_s=budget_s, max_repeats=MAX_RUNS)
    return mesh, timed["result"], timed


def _tip_path(mesh: Any, traj: Any) -> np.ndarray:
    """The tip's mean displacement in every frame, (frames, 3) m."""
    return np.array([tip_mean(mesh, frame - mesh.points) for frame in traj.positions])


def _hammerbot_dynamics(method: str, tolerance: float = TOLERANCE) -> Row:
    import sorofem as sf

    row: Row = {"dt": DYNAMICS_DT, "steps": DYNAMICS_STEPS, "method": method, "tolerance": tolerance,
                "mass_damping": DYNAMICS_MASS_DAMPING, "api": "sorofem.simulate"}
    try:
        mesh, traj, timed = _simulate_hammerbot(method, tolerance, TIMING_BUDGET_S)
    except sf.ConvergenceError as err:
        row.update(converged=False, failure=str(err))
        return row
    iterations, kinetic = np.asarray(traj.iterations), np.asarray(traj.kinetic_energy)
    factorizations = np.asarray(traj.factorizations)
    _, reference, _ = _simulate_hammerbot("newton", REFERENCE_TOLERANCE)
    tip, reference_tip = _tip_path(mesh, traj), _tip_path(mesh, reference)
    deviation = np.linalg.norm(tip - reference_tip, axis=1).max() / np.linalg.norm(reference_tip, axis=1).max()
    seconds = timed["median"]
    row.update(
        tets=mesh.n_tets, converged=True, seconds=seconds, seconds_per_step=seconds / DYNAMICS_STEPS,
        seconds_first=timed["first"], repeats=len(timed["times"]), times=timed["times"],
        iterations=int(iterations.sum()), iterations_per_step=iterations.tolist(),
        mean_iterations_per_step=float(iterations.mean()), max_iterations_per_step=int(iterations.max()),
        factorizations=int(factorizations.sum()), mean_factorizations_per_step=float(factorizations.mean()),
        single_precision_factorizations=traj.single_precision_factorizations,
        max_residual=float(np.max(traj.residuals)), max_tip_deviation_percent=100 * float(deviation),
        cutbacks=int(traj.cutbacks), max_kinetic_energy=float(kinetic.max()), final_kinetic_energy=float(kinetic[-1]),
        tip_displacement=tip[-1].tolist(), note=f"via {row['api']}, method={method!r}, tolerance={tolerance:g}",
    )
    body = sf.Body(mesh, sf.NeoHookean(**HAMMERBOT_MATERIAL))
    body.fix(hammerbot_mesh()[1])
    static = sf.solve_static(body, gravity=HAMMERBOT_GRAVITY, tolerance=TOLERANCE)
    row["static_tip_displacement"] = tip_mean(mesh, static.displacement)
    return row


@case("sorofem/hammerbot-dynamics-1s", "dynamics", quick=True)
def sorofem_hammerbot_dynamics() -> Row:
    return _hammerbot_dynamics("modified")


@case("sorofem/hammerbot-dynamics-1s-newton", "dynamics", quick=True)
def sorofem_hammerbot_dynamics_newton() -> Row:
    return _hammerbot_dynamics("newton")


@case("sorofem/hammerbot-dynamics-1s-linearly-implicit", "dynamics", quick=True)
def sorofem_hammerbot_dynamics_linearly_implicit() -> Row:
    return _hammerbot_dynamics("linearly_implicit")


@case("sorofem/hammerbot-dynamics-1s-fast", "dynamics", quick=True)
def sorofem_hammerbot_dynamics_fast() -> Row:
    return _hammerbot_dynamics("modified", FAST_TOLERANCE)
