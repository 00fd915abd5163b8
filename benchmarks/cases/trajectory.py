"""The trajectory gradient (discrete adjoint of implicit Euler) of the standard hammerbot's swing,
against the forward simulation."""

from __future__ import annotations

import statistics
import time

import numpy as np

from harness import TABLES, Column, Row, Table, case, col, fmt, mib, ratio, status

from .common import HAMMERBOT_GRAVITY, HAMMERBOT_MATERIAL, hammerbot_mesh

TABLES["trajectory"] = Table(
    "Trajectory gradient (sorofem)",
    "The standard hammerbot (E = 100 kPa, nu = 0.4, rho = 1070 kg/m^3) released from rest under gravity, "
    "Rayleigh damping (1.0 1/s, 1e-3 s), 100 steps of 10 ms. Objective J = sum over the frames of the "
    "tip nodes' mean y-displacement squared; gradient by `sf.trajectory_gradient` with respect to "
    "Young's modulus, Poisson's ratio, density and both Rayleigh coefficients: its own forward pass "
    "(every step modified Newton to `sf.simulate`'s default tolerance 1e-8, unsplit: the default "
    "forward run's frames, bit for bit), then the backward sweep factorising each step's Hessian once, "
    "the solve and contractions of the step after it beside each factorisation. By default every state "
    "is kept while the run's states fit 512 MiB (here: none recomputed); with `checkpoint_every=10` only "
    "every 10th state is kept and the backward sweep recomputes the others segment by segment. The "
    "gradient at tolerance 1e-10 shows what the default's residual costs: its time and the largest "
    "relative difference of its entries from the default's. Forward = `sf.simulate` with the defaults "
    "(`modified`, tolerance 1e-8) and with full Newton to 1e-10 (`newton`). The default forward run and "
    "the gradient: medians of 3 rounds that alternate them in one process; the others: one run each. "
    "Memory for 1000 steps: the states the default keeps (all 1001) and those `checkpoint_every = 32` "
    "keeps (32 checkpoints + the last state, one segment's 33 states and the 4 states around the two "
    "steps in flight), each the full DOFs plus the free DOFs' velocities, besides the 1001 frames of "
    "node positions the objective reads.",
    (
        col("case", "case", str),
        col("tets", "tets"),
        Column("conv.", status),
        col("steps", "steps"),
        col("forward, default [s]", "seconds_forward"),
        col("forward, newton 1e-10 [s]", "seconds_forward_tight"),
        col("gradient [s]", "seconds"),
        Column("frames = forward default's", lambda r: {True: "yes", False: "no"}.get(r.get("default_positions_equal_forward"), "-")),
        col("gradient, checkpoints every 10 [s]", "seconds_checkpointed"),
        col("gradient, tolerance 1e-10 [s]", "seconds_tight"),
        Column("tolerance 1e-10: max rel. difference",
               lambda r: fmt(r.get("tight_max_relative_difference"), digits=1)),
        Column("gradient / forward default", lambda r: fmt(ratio(r.get("seconds"), r.get("seconds_forward")))),
        Column("checkpointed / forward default",
               lambda r: fmt(ratio(r.get("seconds_checkpointed"), r.get("seconds_forward")))),
        col("states kept, 1000 steps, default [MiB]", "states_mib_1000"),
        col("states kept, 1000 steps, every 32 [MiB]", "checkpoint_mib_1000"),
        col("positions, 1000 steps [MiB]", "positions_mib_1000"),
        Column("peak RSS [MiB]", mib),
    ),
)


STEPS, DT, DAMPING = 100, 0.01, (1.0, 1e-3)
#: Rounds of the forward simulation (defaults) and the gradient, alternating.
ROUNDS = 3


@case("sorofem/hammerbot-trajectory-gradient", "trajectory")
def sorofem_hammerbot_trajectory_gradient() -> Row:
    import sorofem as sf

    mesh, fixed = hammerbot_mesh()
    material = sf.NeoHookean(**HAMMERBOT_MATERIAL)
    tip = np.flatnonzero(np.abs(mesh.points[:, 0] - mesh.points[:, 0].max()) < 1e-9)

    def objective(x: np.ndarray) -> tuple[float, np.ndarray]:
        u = (x[:, tip, 1] - mesh.points[tip, 1]).mean(axis=1)
        d = np.zeros_like(x)
        d[:, tip, 1] = 2.0 * u[:, None] / tip.size
        return float(np.sum(u * u)), d

    def body() -> sf.Body:
        b = sf.Body(mesh, material)
        b.fix(fixed)
        return b

    kwargs = dict(gravity=HAMMERBOT_GRAVITY, damping=DAMPING)
    names = ["youngs_modulus", "poisson_ratio", "density", "mass_damping", "stiffness_damping"]
    # The ratio's two times alternate, so that both see the same machine load.
    forward_times, gradient_times = [], []
    for _ in range(ROUNDS):
        t0 = time.perf_counter()
        forward = sf.simulate(body(), DT, STEPS, **kwargs)
        t1 = time.perf_counter()
        g = sf.trajectory_gradient(body(), objective, names, dt=DT, steps=STEPS, **kwargs)
        t2 = time.perf_counter()
        forward_times.append(t1 - t0)
        gradient_times.append(t2 - t1)
    t0 = time.perf_counter()
    sf.simulate(body(), DT, STEPS, method="newton", tolerance=1e-10, **kwargs)
    t1 = time.perf_counter()
    checkpointed = sf.trajectory_gradient(body(), objective, names, dt=DT, steps=STEPS, checkpoint_every=10, **kwargs)
    t2 = time.perf_counter()
    tight = sf.trajectory_gradient(body(), objective, names, dt=DT, steps=STEPS, tolerance=1e-10, **kwargs)
    t3 = time.perf_counter()
    n_full = 3 * mesh.n_nodes
    state_bytes = (n_full + n_full - 3 * fixed.size) * 8
    kept = (32 + 1 + 33 + 4) * state_bytes

    def max_relative_difference(other) -> float:
        return max(float(np.max(np.abs(np.ravel(other.gradient[k]) - np.ravel(v)) / np.max(np.abs(np.ravel(v)))))
                   for k, v in g.gradient.items())

    return {
        "tets": mesh.n_tets, "steps": STEPS, "converged": bool(np.isfinite(forward.positions).all()),
        "seconds_forward": statistics.median(forward_times), "seconds": statistics.median(gradient_times),
        "forward_times": forward_times, "gradient_times": gradient_times,
        "seconds_forward_tight": t1 - t0, "seconds_checkpointed": t2 - t1, "seconds_tight": t3 - t2,
        "states_mib_1000": round(1001 * state_bytes / 2**20, 1), "checkpoint_mib_1000": round(kept / 2**20, 1), "positions_mib_1000": round(1001 * n_full * 8 / 2**20, 1),
        "gradient": {k: float(np.ravel(v)[0]) for k, v in g.gradient.items()},
        "checkpointed_max_relative_difference": max_relative_difference(checkpointed),
        "tight_max_relative_difference": max_relative_difference(tight),
        "default_positions_equal_forward": bool(np.array_equal(g.positions, forward.positions)),
        "mean_iterations_per_step": float(np.mean(g.iterations)),
    }
